"""``layered_beam``: the electrode layers' stiffness and mass (thesis case III, Table IV).

The strip is a symmetric sandwich: polymer of thickness t = 2h between two electrode
layers of thickness t_e.  Bending stiffness and mass per length (about the mid-plane,
which is the neutral axis by symmetry):

    EI = E_p w t³/12 + E_e · 2 w ((h + t_e)³ − h³)/3,    ρA = w (ρ_p t + 2 ρ_e t_e).

The thesis identified E_e = 0.98 GPa for platinum, far below bulk Pt (168 GPa): the
electrodes are cracked and porous.  With ``layered_beam`` the polymer modulus is the bare
membrane's (``Y_polymer``, Fig. 11 DMA), otherwise the whole strip's (``Y``, Fig. 9).
Off: a homogeneous strip of the polymer's density.
"""
from __future__ import annotations

from ..parameters import ParamSpec
from .base import Effect
from .viscoelastic import Prony


class HomogeneousSection(Effect):
    stage = "section"
    layered = False
    summary = "homogeneous strip (whole-strip modulus Y, polymer density)"

    def layer_modulus(self, p) -> float:
        """Role hook (the diagnosis translates starts between models): the electrode layers'
        bending stiffness as an added modulus of the polymer section [Pa] (0: none)."""
        return 0.0

    def section(self, p, polymer: Prony, y_factor: float = 1.0) -> tuple[Prony, float]:
        """(EI*(s) as a Prony series [N m²], mass per length ρA [kg/m])."""
        w, t = p["width"], p["t_polymer"]
        return polymer.scaled(y_factor * w * t ** 3 / 12.0), w * t * p["rho_polymer"]


class LayeredBeam(HomogeneousSection):
    id = "layered_beam"
    layered = True
    summary = "electrode layers' stiffness and mass (Y_electrode, t_electrode, rho_electrode)"
    explanation = __doc__
    params = (ParamSpec("Y_polymer", "Pa", 1e5, 5e11, "bare membrane modulus used in the layered section"),)
    requires = ("t_electrode", "rho_electrode", "Y_electrode")
    diagnosis = {
        "free": ("Y_electrode",), "bounds": {"Y_electrode": (1e7, 2e11)},
        "starts": [{"Y_electrode": 1e8}, {"Y_electrode": 1e10}],
        "nested": False,
        "roles": {"stiffness": ("Y_polymer", 1)},            # the bare membrane's modulus takes over Y
        "excitation": "a broadband record spanning the first resonance; even then usually not distinguishable "
                      "from a stiffer Y",
        "reveal": {"spans_resonance": True},
        "signature": [("resonance_error", 1.0)],
    }

    def layer_modulus(self, p) -> float:
        h, te = 0.5 * p["t_polymer"], p["t_electrode"]
        return float(p["Y_electrode"] * 8.0 * ((h + te) ** 3 - h ** 3) / p["t_polymer"] ** 3)

    def section(self, p, polymer: Prony, y_factor: float = 1.0) -> tuple[Prony, float]:
        w, t, te = p["width"], p["t_polymer"], p["t_electrode"]
        h = 0.5 * t
        I_e = 2.0 * w * ((h + te) ** 3 - h ** 3) / 3.0
        EI = polymer.scaled(y_factor * w * t ** 3 / 12.0, offset=p["Y_electrode"] * I_e)
        return EI, w * (t * p["rho_polymer"] + 2.0 * te * p["rho_electrode"])
