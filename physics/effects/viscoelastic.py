"""``viscoelastic``: frequency-dependent storage and loss modulus from DMA measurements.

Thesis §4.3.2 (Fig. 9 IPMC, Fig. 11 Nafion membrane, Fig. 27 IP2C): Nafion is
viscoelastic, its storage and loss moduli rising with frequency.  The tabulated DMA
data are fitted by a generalised Maxwell (Prony) model

    E*(s) = E∞ + Σ_k E_k s τ_k / (1 + s τ_k),   E∞, E_k ≥ 0,

which is causal and passive (loss ≥ 0 at every frequency) and has an exact state-space
form, so both solvers use the same modulus.  Relaxation times are spread over the
measured band (non-negative least squares on the relative error of E' and E'').  An
optional ``dma_scale`` (default 1) multiplies the tabulated modulus, so a sample stiffer or
softer than the one measured by DMA can be identified.  A *free shape* for a material other
than the one measured: with ``ve_slope`` and ``ve_tan_delta`` given (device file or a fit),
the table is replaced by E'(f) = E'(1 Hz)·(1 + ve_slope)^log10(f/1 Hz), E'' = ve_tan_delta·E'
from ``ve_f_lo`` (default: the table's lowest frequency) to the table's highest (E'(1 Hz) from
the table, times ``dma_scale``), fitted by the same Prony series — so the diagnosis can fit the
slope and the loss of another polymer.  Below ``ve_f_lo`` the relaxation has ended (the
rubbery plateau, E → E∞): a polymer that keeps creeping over minutes has a low ``ve_f_lo``,
one with a plateau below its loss peak a higher one; a DMA table rarely reaches below 1 Hz
while step records with long holds do (Ferry, *Viscoelastic Properties of Polymers*, ch. 3).  Off: an elastic modulus (``Y``,
or ``Y_polymer`` with ``layered_beam``), no loss besides Rayleigh damping.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.optimize import nnls

from ..errors import InputError
from ..parameters import ParamSpec, TableSpec
from .base import Effect


@dataclass(frozen=True)
class Prony:
    """E*(s) = E_inf + Σ E_k s tau_k/(1 + s tau_k) [Pa]; arrays E_k, tau_k."""

    E_inf: float
    E_k: tuple[float, ...] = ()
    tau_k: tuple[float, ...] = ()
    max_rel_error: float = 0.0

    def __call__(self, s) -> np.ndarray:
        s = np.asarray(s, dtype=complex)
        out = np.full(s.shape, self.E_inf, dtype=complex)
        for E, t in zip(self.E_k, self.tau_k):
            out += E * s * t / (1.0 + s * t)
        return out

    def scaled(self, factor: float, offset: float = 0.0) -> "Prony":
        """factor·E*(s) + offset (e.g. a humidity factor, then electrode layers)."""
        return Prony(factor * self.E_inf + offset, tuple(factor * e for e in self.E_k), self.tau_k,
                     self.max_rel_error)


class ElasticModulus(Effect):
    stage = "modulus"
    summary = "elastic polymer modulus (Y, or Y_polymer with layered_beam)"

    def polymer_modulus(self, p, layered: bool) -> Prony:
        return Prony(p["Y_polymer"] if layered else p["Y"])

    def modulus_equivalent(self, p, f: float, layered: bool) -> float:
        """Role hook (the diagnosis translates starts between models): the elastic polymer
        modulus [Pa] equivalent to this stage's at ``f`` [Hz]."""
        return float(p["Y_polymer"] if layered else p["Y"])

    def modulus_start(self, value: float, p, f: float, layered: bool) -> dict:
        """Role hook: this stage's parameters giving the polymer modulus ``value`` at ``f``."""
        return {("Y_polymer" if layered else "Y"): float(value)}


class Viscoelastic(ElasticModulus):
    id = "viscoelastic"
    summary = "frequency-dependent storage/loss modulus fitted (Prony) to DMA tables"
    explanation = __doc__
    params = (ParamSpec("dma_scale", "1", 1e-3, 1e3, "factor on the tabulated DMA modulus", optional=True,
                        default=1.0),
              ParamSpec("ve_slope", "1", 0.0, 1.0, "free shape: storage modulus rise per decade (fraction)",
                        optional=True),
              ParamSpec("ve_tan_delta", "1", 0.0, 1.0, "free shape: loss tangent E''/E'", optional=True),
              ParamSpec("ve_f_lo", "Hz", 1e-6, 1e3, "free shape: frequency below which the modulus stops "
                        "relaxing (default: the DMA table's lowest)", optional=True))
    diagnosis = {
        "free": ("ve_slope", "ve_tan_delta", "ve_f_lo"),    # the free shape (starts: the DMA table's own)
        "bounds": {"ve_slope": (0.0, 0.6), "ve_tan_delta": (0.005, 0.6), "ve_f_lo": (1e-3, 20.0),
                   "dma_scale": (0.05, 20.0)},
        "nested": False,
        "roles": {"stiffness": ("dma_scale", 2)},            # dma_scale takes over Y (and Y_polymer)
        "excitation": "a broadband record spanning the first bending resonance (peak shape, frequency-dependent "
                      "stiffness, loss below resonance)",
        "reveal": {"spans_resonance": True},
        "signature": [("resonance_error", 1.0), ("lf_small_lag", 0.5)],
    }

    @classmethod
    def draw_truth(cls, device, rng):
        """A hidden truth for test beds and demos: dma_scale U(0.75, 1.35) on the device's DMA table."""
        s = float(rng.uniform(0.75, 1.35))
        return device.with_params(dma_scale=s), {"dma_scale": s}
    tables = (
        TableSpec("dma", {"freq": "Hz", "storage": "Pa", "loss": "Pa"},
                  "DMA storage and loss modulus of the whole strip vs frequency", optional=False),
        TableSpec("dma_membrane", {"freq": "Hz", "storage": "Pa", "loss": "Pa"},
                  "DMA of the bare membrane (used with layered_beam)", optional=True),
    )

    @classmethod
    def draw_twin(cls, device, rng):
        """A near twin for demos and tests: a polymer with another law than the device's DMA
        table — storage rising U(8, 12) % per decade from its 1 Hz value, loss tangent
        U(0.10, 0.16) — outside ``dma_scale`` (only the free shape reaches it)."""
        import dataclasses
        t = device.tables["dma"]
        f = np.geomspace(0.01, 100, 25)
        tp = {"storage_rise_per_decade": float(rng.uniform(0.08, 0.12)), "tan_delta": float(rng.uniform(0.10, 0.16))}
        E1 = float(np.interp(0.0, np.log10(t["freq"]), t["storage"]))
        Es = E1 * (1 + tp["storage_rise_per_decade"]) ** np.log10(f)
        table = {"freq": f, "storage": Es, "loss": tp["tan_delta"] * Es}
        return dataclasses.replace(device, tables={**device.tables, "dma": table}), tp

    @classmethod
    def diagnosis_start(cls, device) -> dict:
        """Start of the free shape: the shape of the device's DMA table (:func:`dma_shape`) over
        its band."""
        if "dma" not in device.tables:
            return {}
        t = device.tables["dma"]
        return {**dict(zip(("ve_slope", "ve_tan_delta"), dma_shape(t))), "ve_f_lo": float(np.min(t["freq"]))}

    def _storage(self, f: float, layered: bool) -> float | None:
        t = self.device.tables.get("dma_membrane" if layered else "dma")
        if t is None:
            return None
        return float(np.exp(np.interp(np.log(f), np.log(t["freq"]), np.log(t["storage"]))))

    def modulus_equivalent(self, p, f: float, layered: bool) -> float:
        st = self._storage(f, layered)
        return float(p.get("dma_scale", 1.0) * st) if st else float(p["Y"])

    def modulus_start(self, value: float, p, f: float, layered: bool) -> dict:
        st = self._storage(f, layered)
        return {"dma_scale": float(np.clip(value / st, 0.06, 15.0)) if st else 1.0}

    def polymer_modulus(self, p, layered: bool) -> Prony:
        name = "dma_membrane" if layered else "dma"
        if name not in self.device.tables:
            raise InputError(f"viscoelastic with layered_beam needs the table {name!r} in section "
                             f"'viscoelastic' of device {self.device.name!r}")
        t = self.device.tables[name]
        if "ve_slope" in p and "ve_tan_delta" in p:
            f_hi = float(np.max(t["freq"]))
            f_lo = min(float(p.get("ve_f_lo", np.min(t["freq"]))), f_hi / 2.0)
            E1 = float(np.exp(np.interp(0.0, np.log10(t["freq"]), np.log(t["storage"]))))
            return shape_prony(f_lo, f_hi, E1, float(p["ve_slope"]), float(p["ve_tan_delta"])).scaled(
                p.get("dma_scale", 1.0))
        return fit_prony(tuple(t["freq"]), tuple(t["storage"]), tuple(t["loss"])).scaled(p.get("dma_scale", 1.0))


def dma_shape(table) -> tuple[float, float]:
    """(rise per decade, median loss tangent) of a DMA table: the free shape closest to it."""
    lf, ls = np.log10(np.asarray(table["freq"], float)), np.log10(np.asarray(table["storage"], float))
    slope = float(10 ** np.polyfit(lf, ls, 1)[0] - 1.0) if lf.size > 1 else 0.0
    tand = float(np.median(np.asarray(table["loss"], float) / np.asarray(table["storage"], float)))
    return max(slope, 0.0), max(tand, 0.0)


@lru_cache(maxsize=256)
def shape_prony(f_lo: float, f_hi: float, E1: float, slope: float, tan_delta: float) -> Prony:
    """Prony series of the free shape: storage E1·(1 + slope)^log10(f/1 Hz) [Pa] and loss
    tan_delta × storage, from ``f_lo`` to ``f_hi`` [Hz] at four points a decade (at least 16).
    Remembered: a fit asks for the same shape at every frequency response of an evaluation."""
    f = np.geomspace(f_lo, f_hi, max(16, int(np.ceil(4 * np.log10(f_hi / f_lo))) + 1))
    Es = E1 * (1.0 + slope) ** np.log10(f)
    return fit_prony(tuple(f), tuple(Es), tuple(tan_delta * Es))


@lru_cache(maxsize=64)
def fit_prony(freq: tuple, storage: tuple, loss: tuple, per_decade: float = 2.0) -> Prony:
    """Non-negative Prony fit of a DMA table (frequencies in Hz, moduli in Pa)."""
    f, Es, El = (np.asarray(x, dtype=float) for x in (freq, storage, loss))
    if np.any(Es <= 0) or np.any(El < 0):
        raise InputError("DMA table: storage must be positive and loss non-negative")
    w = 2.0 * np.pi * f
    lo, hi = np.log10(1.0 / (3.0 * w.max())), np.log10(3.0 / w.min())
    tau = np.logspace(lo, hi, max(2, int(np.ceil((hi - lo) * per_decade)) + 1))
    wt = w[:, None] * tau[None, :]
    Ast = np.hstack([np.ones((w.size, 1)), wt ** 2 / (1.0 + wt ** 2)]) / Es[:, None]
    Alo = np.hstack([np.zeros((w.size, 1)), wt / (1.0 + wt ** 2)]) / np.maximum(El, 1e-12 * Es)[:, None]
    A = np.vstack([Ast, Alo])
    b = np.concatenate([np.ones(w.size), (El > 0).astype(float)])
    col = np.linalg.norm(A, axis=0)
    x, _ = nnls(A / col, b, maxiter=100 * A.shape[1])
    x = x / col
    keep = x[1:] > 1e-9 * x.max()
    pr = Prony(float(x[0]), tuple(x[1:][keep]), tuple(tau[keep]))
    E = pr(1j * w)
    err = max(np.max(np.abs(E.real / Es - 1.0)), np.max(np.abs(E.imag - El) / np.maximum(El, 1e-12 * Es)))
    return Prony(pr.E_inf, pr.E_k, pr.tau_k, float(err))
