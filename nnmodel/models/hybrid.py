"""``hybrid``: grey-box model — the physics simulator plus a learned correction.

    y[k] = y_phys[k] + f(y[k-1..k-na], u[k..k-nb+1], y_phys[k..k-nb+1], s[k], m[k], rh[k])

``y_phys`` is the tip deflection (m) that :func:`physics.solvers.timedomain.simulate` computes for
the voltage record (device ``device`` with effects ``effects``, input interpolation
``hold`` between samples, RH smoothed by
:func:`physics.compare.model_rh` as for any physics prediction of a measured record);
``s`` are optional internal physics states (``physics_states``: ``cs_up``, the interface
solvent excess in mol/m³, and/or ``current``, the clamp current in A) and the physics
outputs for extra drives (``physics_inputs``: ``v|v|``, ``v^3``; since the physics is
linear in its input, their weighted sum is the physics behind a static odd input
nonlinearity, a Hammerstein front-end the least-squares bypass identifies), ``m`` optional
memory filters (:mod:`nnmodel.models.features`) of the voltage *and of the physics
output* (so the correction can be a frequency-dependent gain on y_phys), ``rh`` the
relative humidity (and its hat weights).  With ``gain_hidden > 0`` a second small MLP G
scales the physics output, y = y_phys (1 + G(x)) + f(...): a missing effect that mostly
changes how far the actuator bends for a given drive (e.g. a saturating double layer)
is then a gain the network learns rather than a signal it must synthesise.  The
correction ``f`` is the ``ff`` / ``narx`` map (linear bypass, least-squares initialised,
plus an MLP) on the *residual* y - y_phys.  With ``na = 0`` the correction is a static map
of delayed inputs and physics outputs (one-step training is then free-run training); with
``na > 0`` it feeds back its own outputs and ``horizon > 1`` trains it in closed loop.
A grey box is never worse than its physics prior on validation: the correction (its
least-squares start, then the trained one) is kept only when it lowers the free-run
validation error below the physics alone, else set to zero
(:func:`~nnmodel.models.base.keep_if_better`; the card's ``reference_start`` says which).

The physics is part of the model: a bundle's card stores the device document (the
parsed YAML of the device file), the effect list and every parameter value, and loading
rebuilds the simulator from the card, not from whatever device file is installed.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from physics.errors import InputError

from .base import NeuralModel
from .features import memory_filters
from .ff import LAG_CHECKS, lag_core
from .lag import LagSimulator, arx_init
from .params import MAX_WIDTH, Part, size

#: internal physics signals the correction may see: name -> (SimulationResult attribute, unit)
PHYSICS_STATES = {"cs_up": ("cs_up", "mol/m^3"), "current": ("current", "A")}
#: extra inputs the physics is also driven with (V0 = std of the training voltage): the
#: physics is linear in its input, so a weighted sum of these runs is the physics driven
#: through a static odd nonlinearity phi(V) = w1 V + w2 V|V|/V0 + w3 V^3/V0^2 (a
#: Hammerstein front-end, e.g. a saturating double layer), and the least-squares bypass
#: of the correction finds the weights
PHYSICS_INPUTS = {"v|v|": lambda u, v0: u * np.abs(u) / v0, "v^3": lambda u, v0: u ** 3 / v0 ** 2}


def _distinct_names(allowed):
    """Parameter check: None, or a list of distinct names among ``allowed``."""
    def check(v):
        if v is None:
            return None
        if not isinstance(v, (list, tuple)) or any(s not in allowed for s in v) or len(set(v)) != len(v):
            return f"a list of distinct names among {sorted(allowed)} (or [])"
        return None
    return check


def _check_effects(v):
    if isinstance(v, str) or (isinstance(v, (list, tuple)) and all(isinstance(e, str) for e in v)):
        return None
    return "an effect list (e.g. 'default', or a list of effect ids as `eap effects` shows them)"


class HybridCore(LagSimulator):
    """Residual lag core with the normalisation of the physics states (buffers, saved
    with the weights) and an optional multiplicative gain head:
    y = y_phys (1 + G(x)) + f(...), G an MLP of the exogenous regressors x started at 0."""

    def __init__(self, *args, n_states: int = 0, n_phys_mem: int = 0, gain_hidden: int = 0, **kw):
        super().__init__(*args, **kw)
        self.register_buffer("state_mean", torch.zeros(n_states, dtype=torch.float64))
        self.register_buffer("state_std", torch.ones(n_states, dtype=torch.float64))
        self.register_buffer("phys_mem_std", torch.ones(n_phys_mem, dtype=torch.float64))
        # normalised y_phys + y_offset = y_phys / std(y): the physical output in output-std units
        self.register_buffer("y_offset", torch.zeros((), dtype=torch.float64))
        self.gain = None
        if gain_hidden:
            self.gain = nn.Sequential(nn.Linear(self.n_x, gain_hidden), nn.Tanh(), nn.Linear(gain_hidden, 1))
            with torch.no_grad():
                self.gain[-1].weight.zero_()
                self.gain[-1].bias.zero_()

    def zero_correction(self) -> None:
        """Reduce the core to the physics alone (map and gain head at zero)."""
        super().zero_correction()
        if self.gain is not None:
            with torch.no_grad():
                self.gain[-1].weight.zero_()
                self.gain[-1].bias.zero_()

    def reference(self, u_all, x, k: int):
        base = u_all[:, k:, 1]
        if self.gain is None:
            return base
        return base + (base + self.y_offset.to(base.dtype)) * self.gain(x)[..., 0]


@dataclass
class HybridPhysics(Part):
    """The hybrid's physics (flat hyper-parameters, first in its recipe and card): the
    simulator's ``device`` and ``effects``, the internal ``physics_states`` and extra
    ``physics_inputs`` the correction sees, the input interpolation ``hold`` (module doc)."""

    ATTR = "physics_settings"
    CHECKS = {"device": lambda v: None if isinstance(v, str) and v else "a device name or YAML path",
              "effects": _check_effects,
              "physics_states": _distinct_names(PHYSICS_STATES),
              "physics_inputs": _distinct_names(PHYSICS_INPUTS),
              "hold": lambda v: None if v in ("cubic", "linear") else "'cubic' or 'linear'"}

    device: str = "ip2c_pedot_water"
    effects: object = "default"
    physics_states: list | None = None
    physics_inputs: list | None = None
    hold: str = "cubic"


class HybridModel(NeuralModel):
    """Physics simulator + neural correction of its output (grey box); the physics settings
    (:class:`HybridPhysics`: ``device``, ``effects`` ...) are given like any setting."""

    kind = "hybrid"
    NEEDS_PHYSICS = True
    DEFAULTS = {"max_time": 600.0, "grad_clip": 1.0}
    MODEL_PARTS = (HybridPhysics,)
    CHECKS = {**LAG_CHECKS, "gain_hidden": size(MAX_WIDTH, zero=True)}
    CHECK_PARAMS = {"max_epochs": 1, "hidden": 8, "device": "ipmc_pt_eg", "effects": "none"}
    CARD_KEYS = ("physics",)
    _LEARNED = NeuralModel._LEARNED + ("physics_", "physics_card_")

    def __init__(self, na: int = 0, nb: int = 20, hidden: int = 32, layers: int = 2, activation: str = "tanh",
                 poly_degree: int = 1, feedthrough: bool = True, arx_init: bool = True, gain_hidden: int = 0,
                 **settings):
        self._set_params_from(locals())

    # ------------------------------------------------------------------ physics
    def _states(self) -> list[str]:
        return list(self.physics_states or [])

    def _n_extra(self) -> int:
        """Physics channels besides the output: states, then the runs with extra inputs."""
        return len(self._states()) + len(self.physics_inputs or [])

    def _physics_model(self):
        if getattr(self, "physics_", None) is None:
            from physics.model import ActuatorModel
            self.physics_ = ActuatorModel(self.device, self.effects)
            self.physics_card_ = _physics_card(self.physics_)
        return self.physics_

    def physics_output(self, u, rh, fs: float | None = None):
        """(deflection [m], extra (n, states + extra inputs)) of the physics part for voltage
        ``u`` [V] and RH ``rh`` [%] (constant, per sample or None): the states in SI units,
        then the deflection [m] for each of ``physics_inputs`` as the drive."""
        from physics.compare import model_rh
        from physics.solvers.timedomain import simulate

        model = self._physics_model()
        fs = float(fs or self.fs_)
        u = np.asarray(u, dtype=float)
        if rh is not None and np.ndim(rh) == 1:
            rh = model_rh(np.asarray(rh, dtype=float), fs)
        if rh is None and model.needs_rh:
            raise InputError(f"the hybrid's physics ({model.device.name}, humidity effect on) needs the "
                             "relative humidity: give rh=")
        t = np.arange(u.size) / fs
        res = simulate(model, None, t, u, rh=rh, hold=self.hold)
        extra = [getattr(res, PHYSICS_STATES[s][0]) for s in self._states()]
        if self.physics_inputs:
            v0 = self.net_.stat("u")[1]
            for name in self.physics_inputs:
                extra.append(simulate(model, None, t, PHYSICS_INPUTS[name](u, v0), rh=rh, hold=self.hold).deflection)
        return res.deflection, (np.stack(extra, 1) if extra else np.zeros((u.size, 0)))

    def _prepare_channels(self, records):
        super()._prepare_channels(records)
        self._physics_model()
        self._cache = {}
        for r in records:
            if r.rh is None and self.physics_.needs_rh:
                raise InputError(f"record {r.name!r} has no relative humidity, which the hybrid's physics "
                                 f"({self.physics_.device.name}, humidity effect on) needs")
            # keyed by the identity of both arrays: records may share one voltage array
            self._cache[(id(r.u), id(r.rh))] = (r.u, r.rh, self.physics_output(r.u, r.rh))
        core = self.net_.core
        m, sd = self.net_.stat("y")
        core.y_offset.fill_(m / sd)
        fm = self.features_
        if fm.n_mem:
            M = np.concatenate([memory_filters(self.net_.norm("y", v[2][0]), fm.taus, fm.fs)
                                for v in self._cache.values()])
            sd = M.std(0)
            sd[~np.isfinite(sd) | (sd <= 1e-12)] = 1.0
            core.phys_mem_std.copy_(torch.as_tensor(sd))
        if self._n_extra():
            S = np.concatenate([v[2][1] for v in self._cache.values()])
            sd = S.std(0)
            sd[~np.isfinite(sd) | (sd <= 0)] = 1.0
            core.state_mean.copy_(torch.as_tensor(S.mean(0)))
            core.state_std.copy_(torch.as_tensor(sd))

    def _release_channels(self):
        self._cache = {}

    def _channels(self, u, rh, y=None):
        """Channels of the correction: voltage and physics output (both delayed), the physics
        states and extra runs (normalised), the memory filters of the voltage and of the
        physics output, and the RH channels."""
        n, fm = self.net_, self.features_
        hit = getattr(self, "_cache", {}).get((id(u), id(rh)))
        yp, S = hit[2] if hit is not None and hit[0] is u and hit[1] is rh else self.physics_output(u, rh)
        un, ypn = n.norm("u", u), n.norm("y", yp)
        cols = [un[:, None], ypn[:, None]]
        core = n.core
        if S.shape[1]:
            cols.append((S - core.state_mean.numpy()) / core.state_std.numpy())
        if fm.n_mem:   # memory of the voltage (and |V|) and of the physics output
            cols.append(fm.memory(u, n))
            cols.append(memory_filters(ypn, fm.taus, fm.fs) / core.phys_mem_std.numpy())
        return np.concatenate(cols, 1), fm.rh_channels(rh, n)

    # ------------------------------------------------------------------ network
    def _build_core(self, features):
        n_states, n_phys_mem = self._n_extra(), len(features.taus)
        return lag_core(self, features, n_tap=2, n_extra=n_states + n_phys_mem, core_cls=HybridCore, residual=True,
                        n_states=n_states, n_phys_mem=n_phys_mem, gain_hidden=self.gain_hidden)

    def _initialise(self, core, train):
        if self.arx_init:
            self.init_report_ = arx_init(core, train)

    def _reference(self):
        return "physics"

    def fit(self, train, val=None):
        if self.linear_start:
            raise InputError("model 'hybrid': linear_start must be false (the hybrid starts from its physics)")
        if self.inputs == "voltage":
            raise InputError("model 'hybrid': inputs must be 'auto' or 'voltage+rh' (its physics part "
                             "needs the relative humidity of every record)")
        return super().fit(train, val)

    # ------------------------------------------------------------------ persistence
    def _card_extra(self):
        self._physics_model()
        return {"physics": self.physics_card_}

    def _restore_extra(self, card_extra):
        card = card_extra.get("physics")
        if card is not None:
            self.physics_, self.physics_card_ = _physics_from_card(card)


# ---------------------------------------------------------------------- physics in the card
def _physics_card(model) -> dict:
    """JSON description of the physics part: device name and document, effects, the SI
    value of every parameter (for reading and for checking on load)."""
    import yaml
    from pathlib import Path

    dev = model.device
    doc = None
    if dev.path and Path(str(dev.path)).is_file():
        doc = yaml.safe_load(Path(str(dev.path)).read_text(encoding="utf-8"))
    return {"device": dev.name, "device_file": str(dev.path) if dev.path else None,
            "device_document": doc, "effects": list(model.effect_ids), "n_modes": model.n_modes,
            "parameters_SI": {k: float(v) for k, v in dev.params.items()},
            "reference_rh_pct": float(dev.reference_rh)}


def _physics_from_card(card: dict):
    """Rebuild the physics part from a bundle card (the stored device document when
    present, so the bundle does not depend on the installed device files)."""
    from physics.device import load_device, parse_device
    from physics.model import ActuatorModel

    doc = card.get("device_document")
    dev = parse_device(doc, where="bundle card physics.device_document") if doc else load_device(card["device"])
    saved = card.get("parameters_SI") or {}
    diff = sorted(k for k, v in saved.items()
                  if k not in dev.params or not np.isclose(dev.params[k], v, rtol=1e-12, atol=0.0))
    if diff:
        raise InputError(f"the physics parameters {diff} of the bundle card differ from its device "
                         f"{dev.name!r}; the bundle is inconsistent")
    model = ActuatorModel(dev, card["effects"], n_modes=int(card.get("n_modes", 4)))
    return model, dict(card)
