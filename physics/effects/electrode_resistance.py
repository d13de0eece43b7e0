"""``electrode_resistance``: distributed surface resistance of the electrodes.

The supply voltage Vin is applied at the clamp (z = 0, end of the copper contacts);
each electrode face has a sheet resistance Rs [Ω/□], i.e. a resistance Rs/w per unit
length, and the polymer between them an admittance w·Y_p(s) per unit length.  The
voltage across the polymer obeys the RC transmission line (thesis §4.5; Chen & Tan 2008)

    U'' = 2 Rs Y_p(s) U,  U(0) = Vin,  U'(L) = 0   ⇒   U(z) = Vin cosh(m (L−z)) / cosh(m L),

m = sqrt(2 Rs Y_p).  The voltage — and with it the charge and the actuation — falls
along the strip, most at high frequency.  Off: equipotential electrodes, U(z) = Vin.
The time solver uses the finite-volume ladder of the same line (segment grid chosen
so that it matches the closed form to better than 0.2 % over the band).
"""
from __future__ import annotations

import numpy as np

from .base import Effect


class EquipotentialElectrodes(Effect):
    stage = "line"
    reference = "reproduced"          # the reference hangs its slices on series_conductances
    summary = "ideal electrodes: the full voltage across the polymer everywhere"

    def distribution(self, s, Yp, p, z) -> np.ndarray:
        """U(z)/Vin at nodes ``z`` [m] for each complex frequency: shape (len(s), len(z))."""
        return np.ones((np.size(s), np.size(z)), dtype=complex)

    def series_conductances(self, p, edges) -> np.ndarray | None:
        """Ladder link conductances [S] (None: all segments at Vin)."""
        return None


class ElectrodeResistance(EquipotentialElectrodes):
    id = "electrode_resistance"
    reference = "reproduced"
    summary = "electrode sheet resistance: RC transmission line from the clamp, voltage falls along the strip"
    explanation = __doc__
    requires = ("Rs",)
    diagnosis = {
        "free": ("Rs",), "bounds": {"Rs": (0.1, 1e4)}, "starts": [{"Rs": 10.0}, {"Rs": 100.0}, {"Rs": 1000.0}],
        "nested": True, "off": {"Rs": 0.0},
        "excitation": "a swept sine or multisine reaching at least 10 Hz (phase lag growing with frequency)",
        "reveal": {"f_hi_min": 10.0},
        "signature": [("hf_phase_lag", 1.0)],
    }

    @classmethod
    def draw_truth(cls, device, rng):
        """A hidden truth for test beds and demos: Rs log-uniform 20–150 Ω/□."""
        rs = float(np.exp(rng.uniform(np.log(20.0), np.log(150.0))))
        return device.with_params(Rs=rs), {"Rs": rs}

    def distribution(self, s, Yp, p, z) -> np.ndarray:
        L = p["L_total"] - p["L_clamp"]
        m = np.sqrt(2.0 * p["Rs"] * np.asarray(Yp, dtype=complex))[:, None]
        # cosh(m(L−z))/cosh(mL) written with decaying exponentials (Re m >= 0), one complex
        # exponential per node: e^{−m(2L−z)} = e^{−2mL}/e^{−mz}.  That quotient is exact to
        # rounding while |e^{−2mL}| ≥ 1e−290 (then Re(m)z ≤ 334 and |e^{−mz}| ≥ 1e−145); the
        # rare rows of longer lines get the far term's own exponential.
        z = np.asarray(z, dtype=float)[None, :]
        near = np.exp(-m * z)
        far_end = np.exp(-2.0 * m * L)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            far = far_end / near
        long_line = np.abs(far_end[:, 0]) < 1e-290
        if long_line.any():
            far[long_line] = np.exp(-m[long_line] * (2.0 * L - z))
        far += near
        far *= 1.0 / (1.0 + far_end)
        return far

    def series_conductances(self, p, edges) -> np.ndarray | None:
        """Conductance of the differential path (top + bottom electrode) between the clamp
        and node 0 (half a segment) and between consecutive segment centres [S]."""
        if p["Rs"] <= 0.0:
            return None
        e = np.asarray(edges, dtype=float)
        centres = 0.5 * (e[1:] + e[:-1])
        gaps = np.diff(np.concatenate([[0.0], centres]))
        return p["width"] / (2.0 * p["Rs"] * gaps)
