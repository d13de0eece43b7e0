"""Parameter specifications: name, SI unit, admissible range and meaning.

The base parameters below are needed by every model; each physical effect declares
its own (see :mod:`physics.effects`).  Device files give every value with its unit
and source; :mod:`physics.device` converts them to SI with these specifications.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ParamSpec:
    """One scalar parameter: ``unit`` is the SI unit values are stored in."""

    name: str
    unit: str
    lo: float
    hi: float
    description: str
    optional: bool = False
    default: float | None = None   # value used when a device file leaves an optional parameter out

    def check(self, value: float, where: str) -> float:
        from .errors import InputError
        if not (self.lo <= value <= self.hi):
            raise InputError(f"{where}: {self.name} = {value:g} {self.unit} is outside the admissible "
                             f"range [{self.lo:g}, {self.hi:g}] {self.unit} ({self.description})")
        return value


@dataclass(frozen=True)
class TableSpec:
    """A tabulated parameter: named columns with SI units (e.g. a DMA modulus table)."""

    name: str
    columns: dict[str, str]
    description: str
    optional: bool = True


def _specs(section_items) -> dict[str, ParamSpec]:
    return {p.name: p for p in section_items}


# Base parameters, grouped by device-file section.
BASE_SECTIONS: dict[str, dict[str, ParamSpec]] = {
    "geometry": _specs([
        ParamSpec("L_total", "m", 1e-4, 1.0, "total strip length Lt, clamp included"),
        ParamSpec("L_clamp", "m", 0.0, 0.5, "length held in the copper clamp contacts Lc"),
        ParamSpec("width", "m", 1e-5, 0.5, "strip width w"),
        ParamSpec("t_polymer", "m", 1e-6, 5e-3, "ionic polymer membrane thickness t_Naf = 2h"),
    ]),
    "electrical": _specs([
        ParamSpec("eps_r", "1", 1.0, 1e12, "relative permittivity of the hydrated polymer (eq. 1)"),
        ParamSpec("sigma_polymer", "S/m", 0.0, 1e3,
                  "electronic (leakage) conductivity of the polymer, the sigma of eq. 1"),
        ParamSpec("Rs", "ohm", 0.0, 1e7,
                  "electrode sheet resistance (ohm per square) of each face (the electrode line)"),
    ]),
    "chemical": _specs([
        ParamSpec("D_cation", "m^2/s", 1e-16, 1e-6, "cation diffusion coefficient D+ (eq. 5)"),
        ParamSpec("C_anion", "mol/m^3", 1e-3, 1e5,
                  "fixed anion concentration = initial cation concentration C+0 (electroneutral)"),
        ParamSpec("C_solvent0", "mol/m^3", 0.0, 1e6, "initial solvent concentration Cs0 (eq. 8)"),
        ParamSpec("n_solvation", "1", 0.0, 100.0, "solvent molecules dragged per cation n+ (eq. 7)"),
        ParamSpec("D_solvent", "m^2/s", 1e-18, 1e-6, "solvent diffusion coefficient Ds (eq. 7)", optional=True),
        ParamSpec("z_cation", "1", 1.0, 3.0, "cation charge number z+"),
        ParamSpec("T_ext", "K", 150.0, 500.0, "ambient (reference) temperature"),
    ]),
    "electrodes": _specs([
        ParamSpec("t_electrode", "m", 1e-9, 1e-3, "thickness of each electrode layer", optional=True),
        ParamSpec("rho_electrode", "kg/m^3", 100.0, 3e4, "electrode density", optional=True),
        ParamSpec("Y_electrode", "Pa", 1e5, 5e11, "electrode Young's modulus (cracked, porous layers)",
                  optional=True),
        ParamSpec("k_electrode", "W/(m K)", 1e-3, 1e3, "electrode thermal conductivity", optional=True),
        ParamSpec("cp_electrode", "J/(kg K)", 1.0, 1e5, "electrode specific heat capacity", optional=True),
    ]),
    "mechanical": _specs([
        ParamSpec("Y", "Pa", 1e5, 5e11, "Young's modulus of the strip when viscoelastic is off"),
        ParamSpec("rho_polymer", "kg/m^3", 100.0, 3e4, "density of the hydrated polymer"),
        ParamSpec("kf", "N m/mol", 0.0, 1e6,
                  "load constant of eq. 9: interface traction per unit interface solvent excess"),
        ParamSpec("beta_f", "s", 0.0, 1.0, "Rayleigh stiffness-damping factor beta_f (alpha_f = 0)"),
    ]),
}
