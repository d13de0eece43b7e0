
import numpy as np
import pytest
import yaml

from physics.device import available_devices, config_dir, load_device, parse_device
from physics.errors import InputError

SHIPPED = ["ipmc_pt_eg", "ip2c_pedot_water"]


def raw(name):
    return yaml.safe_load((config_dir() / "devices" / f"{name}.yaml").read_text())


def test_shipped_devices_are_available_and_load():
    assert set(SHIPPED) <= set(available_devices())
    for n in SHIPPED:
        d = load_device(n)
        assert d.reference_rh == 100.0
        assert {"dma", "dma_membrane"} <= set(d.tables)
        assert {"Y", "kf"} <= set(d.humidity_maps)


@pytest.mark.parametrize("name", SHIPPED)
def test_every_shipped_value_has_a_unit_and_a_source(name):
    r = raw(name)
    n_values = 0
    for sec, body in r.items():
        if not isinstance(body, dict) or sec in ("reference_rh",):
            continue
        for key, entry in body.items():
            assert isinstance(entry, dict)
            assert str(entry.get("source", "")).strip(), f"{sec}.{key} has no source"
            if "value" in entry:
                assert str(entry.get("unit", "")).strip(), f"{sec}.{key} has no unit"
                n_values += 1
            else:  # tables and humidity maps: every column with a unit
                for col, c in entry.items():
                    if isinstance(c, dict):
                        assert str(c.get("unit", "")).strip(), f"{sec}.{key}.{col} has no unit"
    assert n_values > 30


def test_thesis_values_are_converted_to_si():
    ipmc, ip2c = load_device("ipmc_pt_eg"), load_device("ip2c_pedot_water")
    assert ipmc["t_polymer"] == pytest.approx(180e-6)        # 180 um, §2.1
    assert ipmc["T_ext"] == pytest.approx(298.15)            # 25 degC
    assert ipmc["Y_electrode"] == pytest.approx(0.98e9)      # Table IV
    assert ip2c["rho_electrode"] == pytest.approx(1011.0)    # 1.011 g/cm3, Table VI
    assert ip2c["frac_p"] == pytest.approx(53.0)             # eq. 16
    np.testing.assert_allclose(ipmc.humidity_maps["Y"].values, [0.49e9, 0.39e9, 0.225e9, 0.18e9])  # Table V


def _mutated(fn):
    r = raw("ipmc_pt_eg")
    fn(r)
    return r


@pytest.mark.parametrize("mutate,message", [
    (lambda r: r.update(geomtry={}), r"unknown section 'geomtry'.*did you mean geometry"),
    (lambda r: r["geometry"].update(widht={"value": 1, "unit": "mm"}), r"unknown parameter 'widht'.*width"),
    (lambda r: r["geometry"]["width"].pop("unit"), r"geometry\.width: missing unit"),
    (lambda r: r["geometry"]["width"].update(unit="Pa"), r"geometry\.width: unit 'Pa'.*not compatible"),
    (lambda r: r["geometry"]["width"].update(unit="furlong"), r"geometry\.width: unknown unit symbol"),
    (lambda r: r["mechanical"]["beta_f"].update(value=-1), r"mechanical\.beta_f.*outside the admissible range"),
    (lambda r: r["mechanical"]["Y"].update(value="soft"), r"mechanical\.Y: value 'soft' is not a number"),
    (lambda r: r["chemical"].pop("D_cation"), r"section 'chemical' is missing D_cation"),
    (lambda r: r["viscoelastic"]["dma"]["freq"].update(values=[5, 1, 2, 3, 4, 6]), r"dma.*strictly increasing"),
    (lambda r: r["humidity_maps"]["Y"].update(mode="sideways"), r"humidity_maps\.Y: mode must be"),
    (lambda r: r["humidity_maps"].update(Q={"rh": {"values": [1, 2], "unit": "pct"},
                                             "values": {"values": [1, 2], "unit": "1"}}), r"humidity_maps\.Q"),
    (lambda r: r.update(default_effects=["magic"]), r"unknown effect"),
])
def test_bad_device_files_are_rejected_with_the_key_named(mutate, message):
    with pytest.raises(InputError, match=message):
        parse_device(_mutated(mutate), where="my_device.yaml")


def test_error_names_the_file(tmp_path):
    r = _mutated(lambda r: r["geometry"]["width"].pop("unit"))
    p = tmp_path / "custom.yaml"
    p.write_text(yaml.safe_dump(r))
    with pytest.raises(InputError, match=r"custom\.yaml: geometry\.width"):
        load_device(p)
    with pytest.raises(InputError, match="unknown device 'nope'"):
        load_device("nope")


def test_user_device_file_with_own_values(tmp_path):
    r = raw("ipmc_pt_eg")
    r["geometry"]["L_total"] = {"value": 40, "unit": "mm"}          # no source needed in user files
    p = tmp_path / "long.yaml"
    p.write_text(yaml.safe_dump(r))
    d = load_device(p)
    assert d["L_total"] == pytest.approx(0.040)


def test_with_params_checks_ranges():
    d = load_device("ipmc_pt_eg")
    assert d.with_params(kf=0.01)["kf"] == 0.01
    assert d["kf"] == pytest.approx(0.0041)     # the original is unchanged
    with pytest.raises(InputError, match="beta_f"):
        d.with_params(beta_f=5.0)
    with pytest.raises(InputError, match="unknown parameter 'kff'"):
        d.with_params(kff=1.0)
