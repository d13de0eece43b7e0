import numpy as np
import pytest

from physics.io.units import UnitError, parse_unit, to_si


@pytest.mark.parametrize("unit,si", [
    ("GPa", 1e9), ("um", 1e-6), ("g/cm^3", 1000.0), ("mol/L", 1000.0), ("mS", 1e-3), ("ms", 1e-3),
    ("kJ", 1e3), ("pct", 0.01), ("1", 1.0), ("mm", 1e-3),
])
def test_scale_factors(unit, si):
    assert parse_unit(unit).factor == pytest.approx(si)


def test_compound_units_have_the_right_dimension():
    # W/(m^2 K) = kg s^-3 K^-1 ; N m/mol = kg m^2 s^-2 mol^-1 ; m^2/s
    assert parse_unit("W/(m^2 K)").same_dimension(parse_unit("kg/(s^3 K)"))
    assert parse_unit("N m/mol").same_dimension(parse_unit("J/mol"))
    assert parse_unit("ohm").same_dimension(parse_unit("V/A"))
    assert parse_unit("S/m").same_dimension(parse_unit("A/(V m)"))
    assert parse_unit("F/m").same_dimension(parse_unit("C/(V m)"))
    assert not parse_unit("m^2/s").same_dimension(parse_unit("m/s"))


def test_conversion_and_temperature():
    assert to_si(0.98, "GPa", "Pa") == pytest.approx(0.98e9)
    assert to_si(25, "degC", "K") == pytest.approx(298.15)
    assert to_si(1.011, "g/cm^3", "kg/m^3") == pytest.approx(1011.0)
    np.testing.assert_allclose(to_si([1, 2], "mm", "m"), [1e-3, 2e-3])


@pytest.mark.parametrize("bad", ["", "J/kg K", "furlong", "m^", "(m", "m//s", "m/"])
def test_bad_units_are_rejected(bad):
    with pytest.raises(UnitError):
        parse_unit(bad)


def test_incompatible_dimension_names_both_units():
    with pytest.raises(UnitError, match=r"'mm'.*not compatible.*'Pa'"):
        to_si(1.0, "mm", "Pa")
