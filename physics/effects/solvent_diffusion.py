"""``solvent_diffusion``: solvent dragged by the cations and diffusing back (back-relaxation).

Thesis eq. 7: ∂Cs/∂t = −∇·(n⁺ f⁺ − Ds ∇Cs).  Cations carry n⁺ solvent molecules to the
cathode; the excess then diffuses back through the thickness (no-flux faces).  For the
first moment of the solvent excess — the quantity that bends the strip — relative to
its value without diffusion the exact factor is (docs/reference/physics.md)

    B(s) = 1 − tanh(g)/g,   g = h sqrt(s/Ds),

B → 1 at high frequency and B ≈ s h²/(3 Ds) → 0 at DC: the deflection relaxes back with
a time scale ~h²/Ds (≈ 34 s for the IP2C's water, ≈ 1 h for the IPMC's ethylene glycol;
Porfiri, Sharghi & Zhang 2018).  The interface solvent excess Cs_up (eq. 8) is reported
as the first-moment-equivalent interface value, so it carries the same factor.
Off: the solvent stays with the cations (B = 1).
"""
from __future__ import annotations

import numpy as np

from .base import Effect


class SolventDrag(Effect):
    stage = "solvent"
    reference = "reproduced"          # the reference transports the solvent with solvent_diffusivity
    summary = "solvent moves with the cations only (no back-diffusion)"

    def solvent_factor(self, s, p) -> np.ndarray:
        """B(s): first moment of the solvent excess relative to no back-diffusion."""
        return np.ones(np.shape(s), dtype=complex)

    def solvent_diffusivity(self, p) -> float:
        """Ds [m²/s] of the solvent's back-diffusion (0: none), for the reference solver."""
        return 0.0


class SolventDiffusion(SolventDrag):
    id = "solvent_diffusion"
    reference = "reproduced"
    summary = "solvent dragged by cations (n+) and diffusing back (Ds): back-relaxation, time scale h²/Ds"
    explanation = __doc__
    requires = ("D_solvent", "n_solvation")
    # h²/Ds from 0.2 s to 1e5 s, with h² = t_polymer²/4
    diagnosis = {
        "free": ("D_solvent",), "bounds": {"D_solvent": (0.25 / 1e5, 0.25 / 0.2, "t_polymer^2")},
        "starts": [{"D_solvent": (0.25 / x, "t_polymer^2")} for x in (3.0, 30.0, 300.0, 3000.0)],
        "nested": True,                      # in the limit Ds -> 0 (B(s) -> 1), outside the admissible range
        "excitation": "a swept sine starting at 0.5 Hz or lower, or a square pulse/step holding at least 5 s "
                      "(back-relaxation)",
        "reveal": {"f_lo_max": 0.5, "hold_s": 5.0},
        "signature": [("lf_droop_lead", 1.0), ("step_back_relaxation", 1.0)],
    }

    @classmethod
    def draw_truth(cls, device, rng):
        """A hidden truth for test beds and demos: h²/Ds log-uniform 8–60 s (a water-like solvent; the
        IPMC's ethylene glycol is ~1 h)."""
        h = 0.5 * device.params["t_polymer"]
        ds = float(h * h / np.exp(rng.uniform(np.log(8.0), np.log(60.0))))
        return device.with_params(D_solvent=ds), {"D_solvent": ds}

    def solvent_diffusivity(self, p) -> float:
        return float(p["D_solvent"])

    def solvent_factor(self, s, p) -> np.ndarray:
        g = 0.5 * p["t_polymer"] * np.sqrt(np.asarray(s, dtype=complex) / p["D_solvent"])
        out = np.empty_like(g)
        small = np.abs(g) < 1e-2
        gs = g[small] ** 2
        out[small] = gs / 3.0 - 2.0 * gs ** 2 / 15.0 + 17.0 * gs ** 3 / 315.0
        gb = g[~small]
        out[~small] = 1.0 - np.tanh(gb) / gb
        return out
