"""``thermal``: Joule heating along the strip, temperature, and its effect on ion mobility.

Thesis eq. 12: ρ Cp ∂T/∂t − ∇·(k∇T) = Q_T + h_trans (T_ext − T), with Q_T the Joule
heat of the currents (eq. 12.b).  Reduced along the strip: each segment has the heat
capacity and axial conductance of its layers (polymer, electrodes, and the copper
contacts in the clamp) and loses heat by convection from both faces; the ends are
insulated apart from that (thesis §4.5.1–4.5.2: convective flux on the supply and beam
electrodes).  Heat sources: the electrode currents in the sheet
resistance, the ionic current in the bulk resistance and the electronic leakage through
the polymer.  Temperature enters the electrochemistry through the mobility µ = D/(RT)
(eq. 6) — Debye length and ionic conductivity — and, optionally, an Arrhenius
activation energy E_a of D (default 0: eq. 6 only).  The thesis finds a rise of
~1–1.5 °C near the clamp (Fig. 31).  Joule heating is quadratic in the current: in the
frequency domain (small signal) the temperature is T_ext.  Off: isothermal at T_ext.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..parameters import ParamSpec
from .base import Effect


@dataclass(frozen=True)
class ThermalNetwork:
    """Lumped heat network: segment 0 is the clamp, then the free segments."""

    capacity: np.ndarray      # J/K per segment
    links: np.ndarray         # W/K between consecutive segments
    convection: np.ndarray    # W/K to ambient per segment
    T_ext: float              # K


class Isothermal(Effect):
    stage = "temperature"
    reference = "reproduced"          # the reference solver is isothermal too
    summary = "isothermal at T_ext"

    def network(self, p, edges) -> "ThermalNetwork | None":
        """The heat network of the strip (None: isothermal, no heat balance)."""
        return None


class Thermal(Isothermal):
    id = "thermal"
    linear = False
    reference = "unsupported"
    reference_note = "the reference solver is isothermal"
    summary = "Joule heating along the strip -> temperature -> ion mobility (eq. 6, 12)"
    explanation = __doc__
    params = (
        ParamSpec("h_trans", "W/(m^2 K)", 0.0, 1e5, "convective heat-transfer coefficient"),
        ParamSpec("k_polymer", "W/(m K)", 1e-3, 1e3, "polymer thermal conductivity"),
        ParamSpec("cp_polymer", "J/(kg K)", 1.0, 1e5, "polymer specific heat capacity"),
        ParamSpec("t_contact", "m", 0.0, 1e-2, "copper contact thickness (each face)"),
        ParamSpec("k_contact", "W/(m K)", 1e-3, 1e4, "contact thermal conductivity"),
        ParamSpec("rho_contact", "kg/m^3", 100.0, 3e4, "contact density"),
        ParamSpec("cp_contact", "J/(kg K)", 1.0, 1e5, "contact specific heat capacity"),
        ParamSpec("E_a", "J/mol", 0.0, 2e5, "activation energy of D+ (0: mobility by eq. 6 only)", optional=True,
                  default=0.0),
    )
    # not tried by default: Joule heating of ~1 °C changes the ion mobility by well under 1 % (eq. 6), below
    # what a deflection record resolves, and it needs a large-signal time-domain fit (--candidates thermal)
    diagnosis = {
        "free": (), "bounds": {"h_trans": (0.5, 1e4)},
        "nested": True, "off": {"h_trans": 1e5},              # strong convection: the strip stays at T_ext
        "by_default": False,
        "excitation": "long large-amplitude records (Joule heating); not tried by default",
        "reveal": {"amplitude_levels": 2},
        "signature": [("amplitude_dependence", 1.0)],
    }
    requires = ("t_electrode", "rho_electrode", "k_electrode", "cp_electrode", "rho_polymer")

    def network(self, p, edges) -> ThermalNetwork:
        """Heat network for the clamp plus the free segments with ``edges`` [m]."""
        w, t, te, tc = p["width"], p["t_polymer"], p["t_electrode"], p["t_contact"]
        dz = np.concatenate([[p["L_clamp"]], np.diff(edges)])
        rc = w * (p["rho_polymer"] * p["cp_polymer"] * t + 2 * p["rho_electrode"] * p["cp_electrode"] * te)
        kk = w * (p["k_polymer"] * t + 2 * p["k_electrode"] * te)
        rc_c = rc + 2 * w * p["rho_contact"] * p["cp_contact"] * tc
        kk_c = kk + 2 * w * p["k_contact"] * tc
        cap = rc * dz
        cap[0] = rc_c * dz[0]
        kseg = np.full(dz.size, kk)
        kseg[0] = kk_c
        half = 0.5 * dz / kseg                       # thermal resistance of half a segment
        links = 1.0 / (half[:-1] + half[1:])
        conv = 2.0 * w * p["h_trans"] * dz
        return ThermalNetwork(cap, links, conv, p["T_ext"])
