"""From a description to an effect file: drafts of the forms that remain after the best model.

Each forward-selected residual form (:mod:`.forms`) that can be written as an effect gives
an :class:`EffectDraft`, rendered here as one Python file following the effect contract
(:class:`physics.effects.OutputEffect`, README "Adding an effect"): the fitted values as
parameter defaults, the ``diagnosis`` spec filled in (free parameters, bounds and starts
around the fitted values, the off values, the excitation and reveal rule, the residual
signature) and a docstring saying what was seen, with numbers and units.  Passed back
with ``--effects-path`` the file is a diagnosis candidate like any other.

:func:`write_drafts` writes the files into a new folder through the package's output
policy (:func:`physics.outputs.output_folder`: atomic, never over a user's files) and
checks each one against the contract (:func:`check_draft`) before the folder appears.
"""
from __future__ import annotations

import math
import pprint
import textwrap
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

from ..threads import single_threaded
from . import forms as F


#: How a drafted parameter's search range follows its value v: ``log`` v/30…30·v, ``zero``
#: v/1000…20·v (its off value 0 lies just below), ``signed`` −10|v|…10|v|, ``fixed`` its
#: admissible range; a (lo, hi) pair: that search range whatever v (starts spread over it).
RANGES = ("log", "zero", "signed", "fixed")


@dataclass
class Param:
    """A drafted effect parameter: admissible range [lo, hi], value ``default`` (SI) and how
    its search range follows it (:data:`RANGES`)."""

    name: str
    unit: str
    lo: float
    hi: float
    description: str
    default: float
    range: str | tuple = "log"

    @property
    def bounds(self) -> tuple[float, float]:
        v = self.default
        if isinstance(self.range, tuple):
            return max(min(self.range[0], v), self.lo), min(max(self.range[1], v), self.hi)
        lo, hi = {"log": (v / 30.0, v * 30.0), "zero": (v / 1000.0, 20.0 * v), "signed": (-10 * abs(v), 10 * abs(v)),
                  "fixed": (self.lo, self.hi)}[self.range]
        return max(lo, self.lo), min(hi, self.hi)


@dataclass
class EffectDraft:
    """What a form writes as an effect (see the module doc)."""

    form: str
    effect_id: str
    class_name: str
    summary: str
    model: str
    params: list[Param]
    scan: str                        # the parameter started at its value, /3 and ×3 (unknown scale)
    off: dict
    excitation: str
    reveal: dict
    signature: list[tuple[str, float]]
    body: str
    imports: tuple[str, ...] = ()
    seen: str = ""
    evidence: dict = field(default_factory=dict)

    def refit(self, values: dict) -> None:
        """Take ``values`` (fitted jointly with the model) as the defaults; bounds and starts follow."""
        for p in self.params:
            if p.name in values:
                p.default = float(min(max(float(values[p.name]), p.lo), p.hi))

    @property
    def file_name(self) -> str:
        return f"{self.effect_id}.py"

    def diagnosis(self) -> dict:
        return {"free": tuple(p.name for p in self.params),
                "bounds": {p.name: tuple(_num(b) for b in p.bounds) for p in self.params},
                "starts": [{self.scan: _num(v)} for v in self.scan_values()],
                "nested": True, "off": {k: _num(v) for k, v in self.off.items()},
                "excitation": self.excitation, "reveal": {k: _num(v) for k, v in self.reveal.items()},
                "signature": [tuple(s) for s in self.signature]}

    def scan_values(self) -> list[float]:
        import numpy as np
        p = next(q for q in self.params if q.name == self.scan)
        lo, hi = p.bounds
        if isinstance(p.range, tuple) and lo > 0:
            return [p.default] + [float(x) for x in np.geomspace(lo, hi, 6)[:-1]]
        return [min(max(p.default * k, lo), hi) for k in (1.0, 1 / 3.0, 3.0)]

    def source(self) -> str:
        """The effect file's text."""
        doc = "\n\n".join(textwrap.fill(par, 96, break_on_hyphens=False, break_long_words=False) for par in (
            f"{self.summary[0].upper()}{self.summary[1:]} — drafted by `eap diagnose --draft-effects` from what "
            "remained after the best model.",
            f"What was seen: {self.seen}",
            f"Model: {self.model}",
            "Check it with the contract tests (README, \"Adding an effect\") and pass it back with "
            f"``--effects-path {self.file_name}``; edit the defaults, bounds and docstring as you learn more."))
        params = "\n".join(f"        ParamSpec({p.name!r}, {p.unit!r}, {_num(p.lo)!r}, {_num(p.hi)!r}, {p.description!r},"
                           f"\n                  optional=True, default={_num(p.default)!r}),"
                           for p in self.params)
        spec = pprint.pformat(self.diagnosis(), width=100, sort_dicts=False)
        spec = textwrap.indent(spec, " " * 16).strip()
        imports = "".join(f"{line}\n" for line in self.imports)
        return (f'"""{doc}\n"""\n'
                f"{imports}from physics.effects import OutputEffect\nfrom physics.parameters import ParamSpec\n\n\n"
                f"class {self.class_name}(OutputEffect):\n"
                f"    id = {self.effect_id!r}\n"
                f"    summary = {self.summary!r}\n"
                f"    explanation = __doc__\n"
                f"    params = (\n{params}\n    )\n"
                f"    diagnosis = {spec}\n\n"
                f"{self.body}")


def _num(x: float) -> float:
    """A value rounded to 4 significant digits for a readable file."""
    x = float(x)
    return float(f"{x:.4g}") if math.isfinite(x) and x != 0 else x


def drafts(forms: Sequence[F.FormFit], fit, records) -> list[EffectDraft]:
    """A draft of every form of ``forms`` that can be written as an effect, its residual fit
    as the start (the forward-selected first, then by ΔBIC)."""
    res = F.residual_of(fit, records)
    out, seen = [], set()
    for ff in sorted(forms, key=lambda f: (f.selected_step or 99, f.delta_bic)):
        d = F.form_of(ff.form)().draft(ff, res) if ff.form not in seen else None
        if d is None:
            continue
        seen.add(ff.form)
        d.seen = f"in the residual of {fit.spec.label} (RMS error {1e6 * fit.rmse:.4g} µm), {ff.full_text}."
        d.evidence = {"residual_form": ff.to_dict()}
        out.append(d)
    return out


@dataclass
class DraftOutcome:
    """The drafts fitted with the model, forward-selected: kept (in order), rejected, and the
    chain of effects added to the base (kept drafts and any catalog pick, in order)."""

    kept: list
    rejected: list                   # (draft, reason)
    rmse_before: float               # the diagnosis's final model (base, or base + its picks)
    chain: list = field(default_factory=list)     # (effect id, RMS after [m]) per step from the base
    notes: list = field(default_factory=list)
    steps: list = field(default_factory=list)     # (effects fitted on, DiagnosisResult) per round

    @property
    def rmse_after(self) -> float:
        return self.chain[-1][1] if self.chain and self.kept else self.rmse_before

    def lines(self) -> list[str]:
        out = [f"{d.file_name}: {d.evidence['text']}" for d in self.kept]
        out += [f"{d.effect_id} not kept: {why}" for d, why in self.rejected]
        return out + self.notes


@single_threaded
def draft_effects(res, rediagnose, max_effects: int = 2) -> DraftOutcome:
    """Draft what remains after the final model of the diagnosis ``res`` and select the drafts
    by fitting them with the model: ``rediagnose(device, effects, free, candidates)`` runs the
    diagnosis of the records with ``candidates`` (the drafts, registered meanwhile) on top of
    the model ``device`` (fitted values) + ``effects`` with ``free`` parameters.

    Nothing is drafted when there is nothing to explain.  Otherwise, forward from the base, the
    drafts compete with the catalog effects the diagnosis picked, even when the model with them
    is adequate (a catalog effect can mimic physics it does not model within the noise, e.g. the
    electrode resistance a sensor's low-pass): the candidate that lowers the error most (lowest ΔBIC) is taken when it
    passes ΔBIC ≤ −:data:`.forms.SIGNIFICANT_BIC` and ≥ :data:`.forms.MIN_GAIN` lower RMS error,
    and the others are tried again on top of it (at most ``max_effects`` drafts kept).  A kept
    draft takes the values fitted with the model as its defaults (bounds and starts follow)."""
    import tempfile

    from .. import effects as E
    from .candidates import effect_values
    fit = res.final
    ad = res.adequacy
    if res.verdict.status == "nothing to explain" or (ad is not None and ad.adequate and not res.picks):
        items = []
    else:       # an adequate catalog pick may still be a mimic: the drafts compete with it
        items = drafts(ad.forms if ad is not None and ad.forms else F.describe(fit, res.records), fit, res.records)
    outcome = DraftOutcome([], [], fit.rmse)
    if not items:
        return outcome
    base = res.base
    on_top, free, device = list(base.effects), list(base.spec.free), base.device
    catalog = [p.effect for p in res.picks]
    with tempfile.TemporaryDirectory(prefix="eap-drafts-") as tmp:
        ids = []
        for d in items:
            path = Path(tmp) / d.file_name
            path.write_text(d.source(), encoding="utf-8")
            ids += E.load_effects_file(path)
        try:
            pool = list(items)
            while pool and len(outcome.kept) < max_effects:
                again = rediagnose(device, on_top, free, [d.effect_id for d in pool] + catalog)
                outcome.steps.append((list(on_top), again))
                by_id = {c.effect: c for c in again.candidates}
                scored, why = [], {}
                for key in pool + catalog:
                    eid = key if isinstance(key, str) else key.effect_id
                    c = by_id.get(eid)
                    if c is None or not c.evaluated:
                        why[eid] = c.reason if c is not None else "not evaluated"
                        continue
                    gain = 1.0 - c.fit.rmse / again.base.rmse if again.base.rmse > 0 else 0.0
                    dbic = c.comparison.delta_bic
                    if dbic <= -F.SIGNIFICANT_BIC and gain >= F.MIN_GAIN:
                        scored.append((dbic, key, c))
                    else:
                        how = "lowers the RMS error only" if c.fit.rmse <= again.base.rmse else "raises the RMS error"
                        why[eid] = (f"fitted with [{', '.join(on_top)}] it {how} from {1e6 * again.base.rmse:.4g} "
                                    f"to {1e6 * c.fit.rmse:.4g} µm (ΔBIC {dbic:.3g})")
                if not scored:
                    outcome.rejected += [(d, why.get(d.effect_id, "")) for d in pool]
                    break
                scored.sort(key=lambda x: x[0])
                dbic, key, c = scored[0]
                eid = key if isinstance(key, str) else key.effect_id
                values = effect_values(c.fit, eid)
                text = (f"fitted with [{', '.join(on_top)}] it lowers the RMS error from {1e6 * again.base.rmse:.4g} "
                        f"to {1e6 * c.fit.rmse:.4g} µm (ΔBIC {dbic:.4g})")
                rivals = [(b, k) for b, k, _ in scored[1:] if b - dbic < F.SIGNIFICANT_BIC]
                if rivals:
                    text += "; " + ", ".join(f"{k if isinstance(k, str) else k.effect_id} (ΔBIC {b:.4g})"
                                             for b, k in rivals) + " fits almost as well: these records hardly tell them apart"
                if isinstance(key, str):            # the catalog's pick: on the chain, then the drafts on top
                    outcome.notes.append(f"{eid} (the diagnosis's pick) {text}; the drafts are tried on top of it")
                    catalog.remove(key)
                else:
                    key.refit(values)
                    key.evidence.update({"rmse_before_m": again.base.rmse, "rmse_after_m": c.fit.rmse,
                                         "delta_bic": dbic, "on_top_of": list(on_top), "text": text, "values": values})
                    key.seen += " Fitted jointly, " + text[len("fitted "):] + "."
                    outcome.kept.append(key)
                    pool.remove(key)
                outcome.chain.append((eid, c.fit.rmse))
                on_top.append(eid)
                free += [n for n in values if n not in free]
                device = c.fit.device
            else:
                outcome.rejected += [(d, "not tried: the forward selection stopped") for d in pool]
        finally:
            for i in ids:
                E.unregister(i)
    return outcome


@single_threaded
def check_draft(path: Path) -> list[str]:
    """The contract (:func:`physics.effects.check_effect`) run on a written draft; [] when it passes."""
    from .. import effects as E
    classes = E.effect_classes_in_file(path)
    problems = []
    for cls in classes:
        report = E.check_effect(cls)
        if not report.ok:
            problems.append(f"{path.name}: {report}")
    return problems


def write_drafts(items: Sequence[EffectDraft], out, *, overwrite: bool = False, inputs: Sequence = ()) -> dict:
    """Write ``items`` into the new folder ``out`` (atomic; refused over a folder eap did not
    write) with ``README.txt``; each file is checked first.  Returns {file: problems}."""
    from ..outputs import output_folder
    out = Path(out)
    report = {}
    with output_folder(out, inputs=inputs, overwrite=overwrite, flag="--draft-effects") as tmp:
        lines = []
        for d in items:
            path = tmp / d.file_name
            path.write_text(d.source(), encoding="utf-8")
            problems = check_draft(path)
            report[d.file_name] = problems
            lines.append(f"{d.file_name}: {d.summary}; contract check "
                         + ("passed" if not problems else "FAILED: " + "; ".join(problems)))
        (tmp / "README.txt").write_text(
            "Effect files drafted by eap diagnose --draft-effects from what remained after the best model.\n"
            "Pass one back with --effects-path FILE.py to test it as a candidate.\n\n" + "\n".join(lines) + "\n",
            encoding="utf-8")
    return report


__all__ = ["EffectDraft", "Param", "DraftOutcome", "drafts", "draft_effects", "write_drafts", "check_draft"]
