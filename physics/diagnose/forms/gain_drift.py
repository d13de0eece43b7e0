"""A gain that drifts along each record: the response grows or shrinks steadily while the
drive goes on.

Form: e_r ≈ a_r · ((t − t̄_r)/T_r) · ŷ_r, T_r the length of record r and t̄_r its middle: the
response's gain changes by a_r from the start to the end of the record.  An IPMC loses water
while it is driven in open air and its Joule heating warms it, and its gain follows its
water content (the dependence :mod:`physics.effects.humidity` models through the RH), so a
strip that dries during a record answers less and less; a sensor's gain drifts with its
temperature.  Either one gain change shared by the records (the same drying
in each) or one per record (a setup that drifts between them), whichever the evidence prefers
(ΔBIC counts one gain, or one per record).  Unlike a slow pole (creep), which changes only the
slow part of the response, the change acts on every frequency at once; unlike an additive
drift it is proportional to the response.  Fitted on the records whose drive excites the same
band throughout (:func:`stationary`; not a sweep, whose frequency moves with time).  The effect it drafts
(the shared change only: one per record is the setup's, not a model's) scales the simulated
deflection by 1 + g·(t/T − ½), t from the record's start; the response averaged over a
record is unchanged, so g is fitted on the time records; off at g = 0.
"""
from __future__ import annotations

import math

import numpy as np

from ..effect_draft import Param
from .base import Form, FormFit, Residual, time_path_draft


def stationary(v: np.ndarray, fs: float) -> bool:
    """Whether the drive ``v`` (sampled at ``fs`` [Hz]) excites the same band in both halves of the
    record (a multisine, steps, noise): the power-weighted mean log-frequency of the halves within a
    factor 2.  Along a sweep the frequency moves with time, and a gain that changes with time cannot
    be told from one that changes with frequency."""
    h = v.size // 2
    if h < 8:
        return False
    f = np.fft.rfftfreq(h, 1.0 / fs)[1:]
    centres = []
    for x in (v[:h], v[h:2 * h]):
        w = np.abs(np.fft.rfft(x - x.mean()))[1:] ** 2
        if not w.sum() > 0:
            return True             # a half at rest (steps): nothing moves in frequency
        centres.append(float(w @ np.log(f)) / float(w.sum()))
    return abs(centres[0] - centres[1]) < math.log(2.0)


def _ramp(n: int) -> np.ndarray:
    """(t − t̄)/T over a record of ``n`` samples: −½ at its start, +½ at its end."""
    return np.linspace(-0.5, 0.5, n) if n > 1 else np.zeros(n)


class GainDrift(Form):
    id = "gain_drift"
    title = "gain drifting along each record (the strip drying or warming, or the sensor's gain)"

    def fit(self, res: Residual) -> FormFit | None:
        keep = [stationary(r.v_d, r.fs_d) for r in res.records]
        if not any(keep):
            return None
        x = [_ramp(p.size) * p if k else np.zeros_like(p) for p, k in zip(res.preds, keep)]
        own_idx = [i for i, k in enumerate(keep) if k]
        shared = res.regress([[xi] for xi in x], k_grid=0)
        own = res.regress([[xi if j == i else np.zeros_like(xi) for j in own_idx] for i, xi in enumerate(x)],
                          k_grid=0) if len(own_idx) > 1 else shared
        reg = own if own.delta_bic < shared.delta_bic else shared
        gains = reg.gains if reg is own else reg.gains * len(own_idx)
        if reg is shared:
            text = (f"the response's gain changes by {100 * gains[0]:+.2g} % from the start to the end of each "
                    "record (residual ≈ a·((t − t̄)/T)·ŷ, a shared by the records)")
        else:
            text = ("the response's gain changes along each record, by " + ", ".join(f"{100 * g:+.2g} %" for g in gains)
                    + " from start to end (residual ≈ a_r·((t − t̄)/T)·ŷ, a gain change per record)")
        if not all(keep):
            n = len(own_idx)
            text += (f" (in the {'record' if n == 1 else f'{n} records'} whose drive excites the same band throughout; "
                     "along a sweep a gain that changes with time is one that changes with frequency)")
        return self.scored(res, reg, {"gain_change": float(np.mean(gains))}, {"gain_change": "1"},
                           text + ": the strip drying out or warming while driven, or a sensor whose gain drifts",
                           gain_changes=[float(g) for g in gains], per_record=reg is own,
                           records=[r.source for r, k in zip(res.records, keep) if k])

    def draft(self, ff: FormFit, res: Residual) -> list:
        return time_path_draft(
            ff, "gain_drift", "a gain drifting along each record: y·(1 + g·(t/T − ½))",
            "The simulated deflection is scaled by 1 + g·(t/T − ½), t from the record's start and T its length: the "
            "response grows (g > 0) or shrinks steadily while the drive goes on, the same change in every record, "
            "unchanged on average.  A strip drying out or warming while driven, or a sensor's gain drift: check which "
            "before using the model for control.",
            [Param("gain_drift", "1", -0.9, 0.9, "g: change of the gain from a record's start to its end",
                   ff.params["gain_change"], "signed")],
            'y * (1.0 + self.value(p, "gain_drift") * np.linspace(-0.5, 0.5, y.size))',
            "records of the length the model is used for (any input)", "slow_trend")
