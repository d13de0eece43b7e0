"""Static nonlinearities on the input side: a dead-zone or a saturation of the drive
voltage before the (linear) electrochemistry — an amplifier that clips, a contact that
conducts only beyond a threshold, a double layer whose charge grows slower than the voltage.

Form: e ≈ a · H(N(v) − v) + c · H(v), H the fitted linear model (:attr:`.Residual.respond`), v
each record's voltage and N the nonlinearity: the dead-zone N(v) = v − clip(v, −d, d) with d
scanned from 0.5 % to 40 % of the largest |v|, or the saturation N(v) = clip(v, −L, L) with L
from 30 % to 95 % of it, then finer between the grid neighbours of the best.  The saturation is
also fitted as a soft one, :func:`compress` (slope 1 at rest, growing as |v|^γ beyond a knee L:
a charge that saturates logarithmically, as a square root, or towards a bound), on a grid of
knees from 10 % to 3× the largest |v| and of exponents γ from −1 to 0.5, refined; the lower
ΔBIC (which counts the soft law's extra parameter) chooses the law that is reported, and the other law
is drafted beside it when it is a pure map of the drive (its gain in :data:`.PURE`): the fit with the
model decides.  The residual is the model's error, which other missing physics contaminates: beside a
sensor's low-pass the clip won on the residual and a logarithmic map of the drive was drafted as a
clip (8.5× the true model's error), and on a second strip the saturation was 4 % of the residual,
not significant, its clip's gain 1.7.

The second term is there because the base was fitted to the distorted records: if they are
κ·H(N(v)), the fitted gain has taken up part of the distortion and the residual is
(κ − 1)·H(v) + κ·H(N(v) − v), so c = κ − 1 and a = κ.  Without it, a leans on the part of
H(N(v) − v) that looks like H(v) and the threshold comes out wrong (on a test-bed strip with a
0.17 V dead-zone: 0.05 V with a = 1.6 alone, 0.18 V with a/(1 + c) = 0.88 beside H(v)).  A base
whose gain was fitted per RH level has taken up a share of its own at each level, so c is fitted
per level (:attr:`.base.Residual.gain_groups`) and κ is their mean weighted by each level's
‖H(v)‖²: with one c for all, a saturating strip's map lowered the error of its two large records
and raised that of its small record at another level 2.4-fold, and its evidence went against it
(ΔBIC +49, RMS −53 %; with one c per level −1.35e3, −79 %).  The form is significant only with
a/(1 + c) in :data:`.PURE` and every 1 + c > 0 (the pure nonlinearity gives 1; far from it, H of a
part of the voltage only happens to fit a band of error).
Skipped for a large-signal model, or one that maps the voltage already (no H).

Each form drafts an input effect (:class:`physics.effects.InputEffect`) that maps the voltage
before the chain: the diagnosis fits its threshold on the time records; the frequency solver
sees the map as 1, and the coupling gain takes what passes.
"""
from __future__ import annotations

import numpy as np

from ..effect_draft import EffectDraft, Param
from .base import PURE, Form, FormFit, Residual, best_on_grid, refined

#: Exponents γ of the soft saturation's grid (then refined within :data:`SOFT_BOUNDS`): bounded
#: (−1: v/(1 + |v|/L)), logarithmic (0), square-root (0.5).
SOFT_EXPONENTS = (-1.0, -0.5, 0.0, 0.5)
#: Knees L / largest |v| of the soft saturation's grid (from, to, points, geometric) ...
SOFT_KNEES = (0.1, 3.0, 8)
#: ... and the refinement's bounds on L / largest |v| and on γ (γ = 1, the line, is the drafted effect's off value).
SOFT_BOUNDS = ((0.02, 10.0), (-2.0, 0.9))
#: γ is refined as γ + SHIFT: Nelder–Mead's first steps are 5 % of each coordinate, too small around γ = 0.
SHIFT = 3.0


def compress(v, level: float, exponent: float) -> np.ndarray:
    """A soft saturation of the voltage ``v`` [V]: slope 1 at rest and, beyond the knee ``level``
    [V], growth as |v|^``exponent`` — sign(v)·L·((1 + |v|/L)^γ − 1)/γ, the Box–Cox transform of
    1 + |v|/L (Box & Cox, J. R. Stat. Soc. B 26, 211, 1964).  γ = 1 leaves v as it is, 0.5 is a
    square root, 0 a logarithm L·ln(1 + |v|/L), γ < 0 bounded at L/|γ|."""
    v = np.asarray(v, dtype=float)
    x = np.log1p(np.abs(v) / level)
    m = x if abs(exponent) < 1e-9 else np.expm1(exponent * x) / exponent
    return np.sign(v) * level * m


class _InputNonlinearity(Form):
    needs_response = True
    grid: tuple[float, float, int]
    what: str                                       # what the strip does, with {level} [V]
    #: the drafted effect ``drafted_<id>``: param (its threshold [V]), off (the threshold that leaves the
    #: voltage as it is), description, summary, model, body (the map)
    effect: dict

    def distort(self, v: np.ndarray, level: float) -> np.ndarray:
        """N(v) − v for the threshold ``level`` [V]."""
        raise NotImplementedError

    def search(self, res: Residual, vmax: float, columns, pure) -> list[tuple[tuple, "object"]]:
        """[(the law's parameters, regression)] of each law the form knows, the best fit first: the
        threshold on the form's grid, then finer between the neighbours of the best; ``columns(x)``
        gives the regressors for the parameters ``x`` (arguments of :meth:`distort` after the voltage),
        ``pure(reg)`` whether a regression is the pure nonlinearity (:func:`_pure`)."""
        levels = np.geomspace(*self.grid[:2], self.grid[2]) * vmax
        level, reg = best_on_grid(res, levels, lambda x: columns((x,)))
        i = int(np.argmin(np.abs(levels - level)))
        fine = np.geomspace(levels[max(i - 1, 0)], levels[min(i + 1, levels.size - 1)], 9)
        level, reg = best_on_grid(res, fine, lambda x: columns((x,)))
        return [((level,), reg)]

    def fit(self, res: Residual) -> FormFit | None:
        if res.respond is None:
            return None
        volts = [r.v_d for r in res.records]
        vmax = max(float(np.max(np.abs(v))) for v in volts) or 1.0
        linear = [res.respond(k, v) for k, v in enumerate(volts)]
        group = res.gain_groups or [0] * len(volts)
        n_groups = max(group) + 1
        # each group's weight in the records' linear gain: the energy of its linear response
        weights = np.bincount(group, [float(lin @ lin) for lin in linear], minlength=n_groups)

        # record k's H(v) in its group's column, zero in the others' (built once: the scans call columns often)
        gain_cols = [[lin if g == group[k] else np.zeros_like(lin) for g in range(n_groups)]
                     for k, lin in enumerate(linear)]

        def columns(x):
            return [[res.respond(k, self.distort(v, *x))] + gain_cols[k] for k, v in enumerate(volts)]

        def pure(r):
            return _pure(r, weights)
        (x, reg), *others = self.search(res, vmax, columns, pure)
        kappa = _linear_gain(reg, weights)          # the records' linear gain over the fitted model's
        a = reg.gains[0] / kappa if kappa > 0 else float("nan")
        params, units = {"level_V": x[0], "gain": a, "linear_gain": kappa}, {"level_V": "V", "gain": "1",
                                                                            "linear_gain": "1"}
        if len(x) > 1:
            params["exponent"], units["exponent"] = x[1], "1"
        # another law that is a pure map of the drive is drafted beside it: the fit with the model decides
        # (module doc); what the residual shows of it need not be significant there, the form's own may not be
        also = [(y, r) for y, r in others if pure(r)]
        text = self.sentence(x, vmax, a, kappa)
        if also:
            y, r = also[0]
            text = (text[:-1] + f"; the {self.law(y)['title']} (ΔBIC {r.delta_bic:.3g}) is drafted too: the fit with "
                    "the model decides)")
        ff = self.scored(res, reg, params, units, text, v_max_V=vmax)
        if also:
            ff.info["other_law"] = [float(v) for v in also[0][0]]
        ff.admissible = pure(reg)
        ff.significant = ff.significant and ff.admissible
        return ff

    def law(self, x: tuple) -> dict:
        """The effect description (:attr:`effect`) of the law with parameters ``x``."""
        return self.effect

    def sentence(self, x: tuple, vmax: float, a: float, kappa: float) -> str:
        e = self.law(x)
        what = e["what"].format(*(f"{v:.3g}" for v in x))
        return (f"a {e['title']}: {what} ({100 * x[0] / vmax:.0f} % of the largest |v|; "
                f"residual ≈ κ·a·H(N(v) − v) + (κ − 1)·H(v), a = {a:+.3g}, κ = {kappa:.3g}: the records' "
                "linear gain over the model's)")

    def draft(self, ff: FormFit, res: Residual):
        """The law of ``ff`` as an input effect, and the form's other law too when it is a pure map of
        the drive on the residual (``ff.info['other_law']``)."""
        x = (ff.params["level_V"],) + ((ff.params["exponent"],) if "exponent" in ff.params else ())
        other = ff.info.get("other_law")
        return [self._draft(x, ff)] + ([self._draft(tuple(other), ff)] if other else [])

    def _draft(self, x: tuple, ff: FormFit) -> EffectDraft:
        e = self.law(x)
        names = [q[0] for q in e["params"]]
        eid = e.get("id", self.id)
        return EffectDraft(
            form=self.id, effect_id=f"drafted_{eid}", class_name="Drafted" + eid.title().replace("_", ""),
            summary=e["summary"], model=e["model"],
            params=[Param(name, unit, lo, hi, text, value, rng)
                    for (name, unit, lo, hi, text, rng), value in zip(e["params"], x)],
            scan=names[0], off=e["off"],
            excitation="records at two or more drive amplitudes (the share of the voltage the map changes "
                       "depends on the amplitude)",
            reveal={}, signature=[("amplitude_dependence", 1.0), ("harmonics", 0.5)],
            body=("    def filter_input(self, v, fs, p):\n"
                  + "".join(f"        {var} = self.value(p, {name!r})\n" for var, name in zip(e["vars"], names))
                  + f"        return {e['body']}\n"),
            imports=e.get("imports", ("import numpy as np", "")), base="InputEffect",
            starts=[dict(zip(names, st)) for st in e.get("starts", lambda ff: [])(ff)])


class InputDeadZone(_InputNonlinearity):
    id = "input_deadzone"
    title = "dead-zone of the input"
    grid = (0.005, 0.4, 14)
    effect = {"title": title, "what": "the strip does not follow the voltage within ±{0} V",
              "params": [("deadzone_level", "V", 0.0, 1e3, "half width d of the dead-zone", "log")],
              "vars": ["level"], "off": {"deadzone_level": 0.0},
              "summary": "a dead-zone of the drive: the strip sees v − clip(v, −d, d)",
              "model": "The strip is driven by ``v − clip(v, −d, d)``: nothing passes within ±d (a driver or a "
                       "contact that conducts only beyond a threshold); d = 0 is the model without it.",
              "body": "np.asarray(v, float) - np.clip(v, -level, level)"}

    def distort(self, v, level):
        return -np.clip(v, -level, level)


class InputSaturation(_InputNonlinearity):
    id = "input_saturation"
    title = "saturation of the input"
    grid = (0.3, 0.95, 10)
    effect = {"title": title, "what": "the drive acts as if clipped at ±{0} V",
              "params": [("saturation_level", "V", 0.0, 1e3, "level L at which the drive clips", "log")],
              "vars": ["level"], "off": {"saturation_level": 1e3},
              "summary": "a saturation of the drive: the strip sees clip(v, −L, L)",
              "model": "The strip is driven by ``clip(v, −L, L)`` (an amplifier that clips); a level above every "
                       "drive, e.g. 1000 V, is the model without it.",
              "body": "np.clip(v, -level, level)"}
    soft = {"title": "soft saturation of the input", "id": "input_soft_saturation",
            "what": "beyond a knee of ±{0} V the drive acts as if growing as |v|^γ, γ = {1}",
            "params": [("saturation_knee", "V", 1e-3, 1e3, "knee L beyond which the drive's effect saturates", "log"),
                       ("saturation_exponent", "1", SOFT_BOUNDS[1][0], 1.0,
                        "exponent γ of the growth beyond the knee (1: none, 0.5: square root, 0: logarithm, "
                        "< 0: bounded)", SOFT_BOUNDS[1])],
            "vars": ["knee", "exponent"], "off": {"saturation_exponent": 1.0},
            "summary": "a soft saturation of the drive: the strip sees sign(v)·L·((1 + |v|/L)^γ − 1)/γ",
            "model": "The strip is driven by ``compress(v, L, γ)`` = sign(v)·L·((1 + |v|/L)^γ − 1)/γ: slope 1 "
                     "at rest and growth as |v|^γ beyond the knee L (a double layer whose charge grows slower "
                     "than the voltage: γ = 0.5 a square root, γ = 0 a logarithm, γ < 0 towards a bound); "
                     "γ = 1 is the model without it.",
            "body": "compress(v, knee, exponent)",
            # the residual's estimate can lie on a ridge (a knee far beyond the drive with a small
            # curvature); the time records choose among the grid's exponents at two knees
            "starts": lambda ff: [(k * ff.info["v_max_V"], g) for k in (0.25, 1.0) for g in SOFT_EXPONENTS],
            "imports": ("from physics.diagnose.forms.input_side import compress", "")}

    def distort(self, v, level, exponent=None):
        return (np.clip(v, -level, level) if exponent is None else compress(v, level, exponent)) - v

    def law(self, x):
        return self.effect if len(x) == 1 else self.soft

    def search(self, res, vmax, columns, pure):
        """The clip's threshold, and the soft law's knee and exponent (grid, then refined); the
        lower ΔBIC first."""
        [(x, reg)] = super().search(res, vmax, columns, pure)
        grid = [(k, g + SHIFT) for g in SOFT_EXPONENTS for k in np.geomspace(*SOFT_KNEES[:2], SOFT_KNEES[2])]

        def soft(z):        # z: knee / largest |v|, and γ + SHIFT (Nelder–Mead first steps 5 % of a coordinate)
            return columns((z[0] * vmax, z[1] - SHIFT))
        best = best_on_grid(res, range(len(grid)), lambda i: soft(grid[int(i)]), 2, admit=pure)
        if best is None:
            return [(x, reg)]
        (k, g), reg2 = refined(res, list(grid[int(best[0])]), [SOFT_BOUNDS[0], tuple(b + SHIFT for b in SOFT_BOUNDS[1])],
                               soft, 2, admit=pure)
        return sorted([(x, reg), ((k * vmax, g - SHIFT), reg2)], key=lambda law: law[1].delta_bic)


def _linear_gain(reg, weights) -> float:
    """κ: the records' linear gain over the fitted model's, 1 + c of the regression
    e ≈ a'·H(N(v) − v) + Σ_g c_g·H(v)·[record in g] (one c per group of records whose gain the fit
    set together, :attr:`.Residual.gain_groups`), averaged with the ``weights`` of the groups; NaN
    when a group's κ is not positive."""
    kappas = 1.0 + np.asarray(reg.gains[1:], float)
    return float(np.dot(weights, kappas) / np.sum(weights)) if np.all(kappas > 0) else float("nan")


def _pure(reg, weights) -> bool:
    """Whether the regression e ≈ a'·H(N(v) − v) + Σ_g c_g·H(v) is the pure nonlinearity: every
    κ_g = 1 + c_g > 0 and a = a'/κ in :data:`.PURE` (κ: :func:`_linear_gain`).  The soft law needs it
    while it is fitted: a knee far beyond the drive with γ near 1 leaves only a small curvature of the
    voltage, and a large a can fit any band of error with it (a held-out strip's residual took a = 84 at
    a knee 10× its largest drive)."""
    kappa = _linear_gain(reg, weights)
    return kappa > 0 and PURE[0] <= reg.gains[0] / kappa <= PURE[1]
