import numpy as np
import pytest

from physics.errors import InputError
from physics.io.frfdata import FRFData, read_frf, write_frf

H = "freq_Hz,mag_m_per_V,phase_deg\n"


def write(tmp_path, text, name="frf.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_reads_magnitude_phase_coherence_rh(tmp_path):
    p = write(tmp_path, "freq_Hz,mag_mm_per_V,phase_deg,coherence,rh_pct\n"
                        "1,2,0,0.9,40\n2,1,-90,1,40\n4,0.5,180,0.5,41\n")
    frf = read_frf(p)
    np.testing.assert_array_equal(frf.freq, [1, 2, 4])
    np.testing.assert_allclose(frf.response, [2e-3, -1e-3j, -0.5e-3], atol=1e-18)
    np.testing.assert_allclose(frf.magnitude, [2e-3, 1e-3, 0.5e-3])
    np.testing.assert_array_equal(frf.coherence, [0.9, 1, 0.5])
    np.testing.assert_array_equal(frf.rh, [40, 40, 41])
    assert frf.source == str(p) and frf.meta == {}


def test_round_trip_with_unwrapped_phase_and_sidecar(tmp_path):
    f = np.logspace(-1, 2, 60)
    h = 1e-3 / (1 + 1j * f / 20) ** 3  # three poles at 20 Hz: phase -3 atan(f/20), to -236 deg
    frf = FRFData(f, h, coherence=np.linspace(0.2, 1, 60), rh=55.0, meta={"device": "IP2C"})
    np.testing.assert_allclose(frf.phase_deg, -3 * np.degrees(np.arctan(f / 20)), atol=1e-9)
    out = write_frf(frf, tmp_path / "o.csv")
    phase_in_file = np.loadtxt(out, delimiter=",", skiprows=1)[:, 2]
    assert phase_in_file.min() < -230  # written unwrapped, not folded into (-180, 180]
    back = read_frf(out)
    np.testing.assert_array_equal(back.freq, f)
    np.testing.assert_allclose(back.response, h, rtol=1e-14)
    np.testing.assert_array_equal(back.coherence, frf.coherence)
    np.testing.assert_array_equal(back.rh, np.full(60, 55.0))
    assert back.meta == {"device": "IP2C"}


def test_optional_columns_may_be_absent(tmp_path):
    frf = read_frf(write(tmp_path, H + "1,1e-3,10\n2,2e-3,20\n"))
    assert frf.coherence is None and frf.rh is None
    np.testing.assert_allclose(frf.phase_deg, [10, 20])


def test_writer_protects_inputs(tmp_path):
    src = write(tmp_path, H + "1,1e-3,10\n2,2e-3,20\n")
    frf = read_frf(src)
    with pytest.raises(InputError, match="input file"):
        write_frf(frf, src, overwrite=True, protect=(src,))
    with pytest.raises(InputError, match="already exists"):
        write_frf(frf, src)


@pytest.mark.parametrize("kwargs, msg", [
    (dict(freq=[1.0, 1.0]), "point 1, freq: 1.0 Hz is not above"),
    (dict(freq=[0.0, 1.0]), "point 0, freq: 0.0 Hz is not positive"),
    (dict(coherence=[0.5, 1.5]), "point 1, coherence: value 1.5 is outside 0–1"),
    (dict(rh=101.0), "rh 101.0 % is outside 0–100"),
    (dict(response=[1.0, np.nan]), "point 1, response"),
    (dict(response=[1.0]), "response must be a 1-D array of 2 values"),
], ids=["increasing", "positive", "coherence", "rh", "nan", "length"])
def test_object_validates(kwargs, msg):
    with pytest.raises(InputError, match=msg):
        FRFData(**{"freq": [1.0, 2.0], "response": [1.0, 1.0], **kwargs})


BAD = {  # id: (file text, substrings the message must contain)
    "missing-phase": ("freq_Hz,mag_m_per_V\n1,1\n2,1\n", ["missing column phase_deg"]),
    "missing-mag": ("freq_Hz,phase_deg\n1,1\n2,1\n", ["missing column mag_m_per_V or mag_mm_per_V"]),
    "unknown-column": ("freq_Hz,mag_m_per_V,phase_deg,gain_dB\n1,1,0,0\n2,1,0,0\n",
                       ["unknown column 'gain_dB'", "coherence"]),
    "unparseable-unit": ("freq_kHz,mag_m_per_V,phase_deg\n1,1,0\n2,1,0\n",
                         ["column 'freq_kHz'", "cannot parse unit 'kHz'", "Hz"]),
    "nan": (H + "1,1,0\n2,nan,0\n", ["line 3", "column 'mag_m_per_V'", "not finite"]),
    "not-a-number": (H + "1,1,0\n2,1,x\n", ["line 3", "column 'phase_deg'", "'x' is not a number"]),
    "freq-not-positive": (H + "-1,1,0\n2,1,0\n", ["line 2", "freq", "not positive"]),
    "freq-not-increasing": (H + "1,1,0\n3,1,0\n2,1,0\n", ["line 4", "freq", "strictly increasing"]),
    "coherence-above-1": ("freq_Hz,mag_m_per_V,phase_deg,coherence\n1,1,0,1\n2,1,0,1.01\n",
                          ["line 3", "coherence", "1.01", "0–1"]),
    "negative-magnitude": (H + "1,1,0\n2,-1,0\n", ["line 3", "column 'mag_m_per_V'", "negative"]),
    "rh-out-of-range": ("freq_Hz,mag_m_per_V,phase_deg,rh_pct\n1,1,0,50\n2,1,0,150\n",
                        ["line 3", "rh", "150.0", "0–100"]),
    "empty-file": ("", ["empty file"]),
    "header-only": (H, ["empty file"]),
}


@pytest.mark.parametrize("rule", list(BAD))
def test_bad_file_is_rejected_with_a_precise_message(tmp_path, rule):
    text, parts = BAD[rule]
    p = write(tmp_path, text, f"{rule}.csv")
    with pytest.raises(InputError) as err:
        read_frf(p)
    message = str(err.value)
    assert str(p) in message, message
    for part in parts:
        assert part in message, f"{part!r} not in {message!r}"


def test_not_found_and_wrong_extension(tmp_path):
    with pytest.raises(InputError, match=r"none\.csv: file not found"):
        read_frf(tmp_path / "none.csv")
    with pytest.raises(InputError, match=r"frf\.mat: unsupported file type '\.mat'; expected \.csv"):
        read_frf(write(tmp_path, H, "frf.mat"))
