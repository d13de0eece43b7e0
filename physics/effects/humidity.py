"""``humidity``: parameters that depend on relative humidity.

Nafion's water uptake changes with RH, and with it the stiffness and the
electromechanical coupling: thesis Table V identifies, for the IPMC at RH 40/60/80/100 %,
Y = 0.49/0.39/0.225/0.18 GPa and kf = 0.21/0.312/0.15/0.17 N m/mol (drier is stiffer,
so the resonance moves with RH; Brunetto et al. 2010).  A device file lists such maps
under ``humidity_maps`` (``mode: ratio`` — relative to the value at the device's
reference RH — or ``absolute``), for ``Y``, ``kf`` or any other parameter (user maps,
e.g. ``D_cation`` or ``Rs``).  Values are interpolated linearly in RH and held constant
outside the tabulated range (with a warning).  The ``Y`` map scales the polymer modulus in
every mechanical variant (``Y``, ``Y_polymer`` or the DMA modulus); the ``kf`` map scales
``kf0`` as well.  RH may vary in time (slowly, compared with the mechanics).
Off: parameters are those of the reference RH whatever the RH.
"""
from __future__ import annotations

import warnings

import numpy as np

from .base import Effect

# Parameters whose maps act on the mechanical chain only (no re-solve of the electrochemistry).
MECHANICAL_MAPS = ("Y", "Y_polymer", "kf", "kf0")
#: An RH reading up to this far [% RH] outside a map's range takes the end value without a
#: warning: a map identified per RH level spans the levels' means, and a hygrometer's readings
#: jitter about them by about this much (the records' grouping tolerance, ``--rh-tolerance``).
RH_MARGIN = 1.0


class HumidityInvariant(Effect):
    stage = "humidity"
    summary = "parameters independent of RH (those at the device's reference RH)"

    def factors(self, rh) -> dict[str, np.ndarray]:
        """Multiplicative factor of each RH-dependent parameter at ``rh`` [%]."""
        return {}

    def stiffness_factor(self, rh):
        return self.factors(rh).get("Y", np.ones(np.shape(rh)))

    def coupling_factor(self, rh):
        return self.factors(rh).get("kf", np.ones(np.shape(rh)))

    def params_at(self, base: dict, rh: float) -> dict:
        """Parameters at ``rh`` (the Y factor is applied by the beam section, not here)."""
        return self._mapped(base, rh, ("Y",))

    def chain_params(self, base: dict, rh: float) -> dict:
        """Parameters at ``rh`` for the stages after the electrochemistry (load filters, beam)
        of a time record: every map but the stiffness's and the coupling's, whose factors the
        time solver applies sample by sample (a per-RH damping ``beta_f`` or solvent ``D_solvent``,
        as the frequency solver has them at that RH)."""
        return self._mapped(base, rh, MECHANICAL_MAPS)

    def _mapped(self, base: dict, rh: float, skip) -> dict:
        """``base`` with the humidity factors at ``rh`` applied, except to the names in ``skip``
        (a map on ``kf`` scales ``kf0`` alike)."""
        p = dict(base)
        for name, f in self.factors(rh).items():
            if name in skip:
                continue
            if name in p:
                p[name] = p[name] * float(f)
            if name == "kf" and "kf0" in p:
                p["kf0"] = p["kf0"] * float(f)
        return p

    def electrochemistry_varies(self) -> bool:
        """True when RH changes parameters upstream of the mechanics (needs a re-solve)."""
        return any(n not in MECHANICAL_MAPS for n in self.factors(50.0))


class Humidity(HumidityInvariant):
    id = "humidity"
    needs_rh = True
    diagnosis = {
        # once per RH level: kf and Y as in the thesis's Table V, and the damping beta_f — a strip's
        # loss changes with its water content (water plasticises the polymer) and, at a fixed damping
        # ratio, a stiffness that changes with RH moves the stiffness-proportional beta_f with it
        "free": (), "per_rh": ("kf", "Y", "beta_f"),
        "nested": True,
        "excitation": "records at two or more RH levels at least 10 % apart",
        "reveal": {"rh_levels": 2},
        "signature": [("rh_dependence", 1.0)],
    }

    @classmethod
    def draw_truth(cls, device, rng):
        """A hidden truth for test beds and demos: every humidity map of the device raised to a power
        U(0.7, 1.3) about the reference RH (the RH dependence 30 % weaker to 30 % stronger)."""
        import dataclasses
        g = float(rng.uniform(0.7, 1.3))
        maps = {}
        for name, m in device.humidity_maps.items():     # replace() on the maps: no import of physics.device
            ref = float(np.interp(device.reference_rh, m.rh, m.values))
            maps[name] = dataclasses.replace(m, values=ref * (m.values / ref) ** g,
                                             source=f"{m.source} (power {g:.3g})")
        return dataclasses.replace(device, humidity_maps=maps), {"humidity_power": g}
    summary = "RH-dependent parameters: Y(RH), kf(RH) of Table V, user maps for others"
    explanation = __doc__

    def __init__(self, device):
        super().__init__(device)
        if not device.humidity_maps:
            from ..errors import InputError
            raise InputError(f"humidity needs 'humidity_maps' in device {device.name!r} "
                             f"({device.path or 'in memory'})")
        self._at: dict[float, dict] = {}

    def factors(self, rh) -> dict[str, np.ndarray]:
        # one RH level is asked for several times per model evaluation (its parameters, its
        # stiffness, its response): remembered per instance while it raises no warning
        known = self._at.get(rh) if isinstance(rh, float) else None
        if known is not None:
            return dict(known)
        out = self._factors(rh)
        if isinstance(rh, float) and self._in_range(rh):
            self._at[rh] = dict(out)
        return out

    def _in_range(self, rh: float) -> bool:
        return not any(_outside(m, rh, rh) for m in self.device.humidity_maps.values())

    def _factors(self, rh) -> dict[str, np.ndarray]:
        rh = np.asarray(rh, dtype=float)
        # the range checked once per call, as floats: a fit evaluates this millions of times
        lo, hi = (float(rh.min()), float(rh.max())) if rh.size else (np.inf, -np.inf)
        out = {}
        for name, m in self.device.humidity_maps.items():
            if _outside(m, lo, hi):
                warnings.warn(f"RH {lo:.4g}–{hi:.4g} % is outside the "
                              f"{m.rh[0]:g}–{m.rh[-1]:g} % range of the {name} map of device "
                              f"{self.device.name!r}; the end value is used", stacklevel=3)
            base = self.device.params.get(name, 1.0)
            out[name] = m.factor(rh, base, self.device.reference_rh)
        return out


def _outside(m, lo: float, hi: float) -> bool:
    """Whether RH readings from ``lo`` to ``hi`` [%] leave the range of the humidity map ``m`` by
    more than :data:`RH_MARGIN`."""
    return lo < m.rh[0] - RH_MARGIN or hi > m.rh[-1] + RH_MARGIN
