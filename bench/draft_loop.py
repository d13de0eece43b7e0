"""The out-of-catalog loop from the command line, per truth and seed: diagnosis → drafted
effects → diagnosis again with the drafts → the error before and after, against the true
model's error.

    python bench/draft_loop.py [--suites outside,lab,perturbed] [--truths creep,lowpass,drift]
        [--seeds 0,1,2]

Suites: ``outside`` — :func:`physics.testbeds.demo.outside_catalog_case` exported as a lab does
(the bare device, a sweep and a pulse, 60 s at 200 Hz, tip in mm, no metadata; its ``drift`` is
a deterministic A·(1 − e^(−t/τ)) shared by the records); ``lab`` and ``perturbed`` — the test
beds of :mod:`physics.testbeds.cases` (lab-like exports of our simulator with the device's
default effects; a simulator whose base differs a little; their ``drift`` is a random wander,
different in every record).  The records are written as files and ``eap diagnose`` reads them
as a user would, with ``--draft-effects``, then again with the kept drafts (``--effects-path``).
Printed per case: the truth, the first verdict (pick or none, status, RMS error of its final
model), the noise floor its adequacy compares with, the true model's error (scored like the
diagnosis: each record's offset and linear drift removed), the kept drafts (contract check), the
second verdict with the drafts' fitted values, and the wall time.  The machine may be shared: the wall
times are indicative.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import re
import tempfile
import time
from pathlib import Path


def _run(argv: list[str]) -> tuple[str, float]:
    from nnmodel.app.cli import main
    out = io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        code = main(argv)
    if code != 0:
        raise SystemExit(f"eap {' '.join(argv)} failed ({code}):\n{out.getvalue()}")
    return out.getvalue(), time.perf_counter() - t0


def _um(x) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{1e6 * x:.3g}"


def _verdict(d: dict) -> str:
    """Pick (or the ambiguous ones) with the RMS error [µm] of the final model, status and label."""
    v = d["verdict"]
    rmse = {r["effect"]: r.get("rmse_after") for r in d["ranking"]}
    picks = [p["effect"] for p in v.get("chain", [])] or list(v.get("ambiguous") or [])
    named = " / ".join(f"{p} {_um(rmse.get(p))}" for p in picks) or f"no pick, base {_um(d['base']['rmse'])}"
    return f"{named} ({v['status']}" + (f", {v.get('confidence_label')})" if v.get("missing_effect") else ")")


def _records(suite: str, truth: str, seed: int, folder: Path) -> tuple[list[str], list[str], dict, float]:
    """(files, device/effects arguments, truth parameters, true model's error [m])."""
    if suite == "outside":
        from physics.testbeds.demo import outside_catalog_case
        from physics.analysis.metrics import remove_nuisance
        from physics.io.timeseries import write_timeseries
        ms, tp, clean = outside_catalog_case(truth, seed, fs=200.0, duration=60.0, lab=True, clean=True)
        err = [remove_nuisance(m.deflection - y, m.time) for m, y in zip(ms, clean)]
        files = [str(write_timeseries(m, folder / f"{m.source}.csv", units={"deflection": "mm"})) for m in ms]
        return files, ["--device", "ipmc_pt_eg", "--effects", "none"], tp, \
            math.sqrt(sum(float(e @ e) for e in err) / sum(e.size for e in err))
    from physics.testbeds.cases import make_case
    case = make_case(suite, truth, seed)
    files = [str(f) for f in case.write(folder)]
    return files, ["--device", case.device_name, *case.param_args(), "--effects", case.effects], \
        case.truth_params, case.true_error()


def case(suite: str, truth: str, seed: int, tmp: Path) -> dict:
    from physics.effects import EFFECTS, unregister
    files, model, tp, true_error = _records(suite, truth, seed, tmp / "records")
    out, t1 = _run(["diagnose", *files, *model, "--out", str(tmp / "dx"), "--quiet", "--draft-effects",
                    str(tmp / "drafts")])
    first = json.loads((tmp / "dx" / "diagnosis.json").read_text())
    drafts = sorted((tmp / "drafts").glob("*.py")) if (tmp / "drafts").is_dir() else []
    checks = dict(re.findall(r"draft: \S*?(\w+\.py): contract check (passed|FAILED)", out))
    ad = first["verdict"].get("adequacy") or {}
    row = {"truth": tp, "true_error_m": true_error, "noise_floor_m": ad.get("noise_floor_m", first.get("noise_floor_m")),
           "base_m": first["base"]["rmse"], "first": _verdict(first), "seconds": [t1],
           "drafts": {p.name: checks.get(p.name, "?") for p in drafts},
           "not_kept": re.findall(r"draft: (\w+) not kept: .*?(lowers the RMS error only|raises the RMS error) "
                                  r"from ([\d.]+) to ([\d.]+) µm", out)}
    if drafts:
        argv = ["diagnose", *files, *model, "--out", str(tmp / "dx2"), "--quiet"]
        for p in drafts:
            argv += ["--effects-path", str(p)]
        try:
            _, t2 = _run(argv)
        finally:
            for i in [i for i in EFFECTS if i.startswith("drafted_")]:
                unregister(i)
        second = json.loads((tmp / "dx2" / "diagnosis.json").read_text())
        row["second"] = _verdict(second)
        row["fitted"] = {k: x for r in second["ranking"] if r["effect"].startswith("drafted_")
                         for k, x in r.get("effect_parameters", {}).items()}
        row["seconds"].append(t2)
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--suites", default="outside,lab,perturbed")
    ap.add_argument("--truths", default="creep,lowpass,drift")
    ap.add_argument("--seeds", default="0,1,2")
    args = ap.parse_args()
    print("errors [µm]: RMS of the final model; true = the true model's error, scored the same way\n")
    for suite in args.suites.split(","):
        for truth in args.truths.split(","):
            for seed in (int(s) for s in args.seeds.split(",")):
                with tempfile.TemporaryDirectory(prefix="eap-draft-loop-") as tmp:
                    r = case(suite, truth, seed, Path(tmp))
                tp = ", ".join(f"{k} {v:.4g}" for k, v in r["truth"].items())
                print(f"{suite} {truth} seed {seed} (truth: {tp})")
                print(f"  1. base {_um(r['base_m'])} → {r['first']}; noise floor {_um(r['noise_floor_m'])}; "
                      f"true model {_um(r['true_error_m'])}")
                print("  2. drafts kept: " + (", ".join(f"{k} (contract {v})" for k, v in r["drafts"].items())
                                              or "none") + "".join(f"; {d} not kept ({a} → {b})"
                                                                   for d, _, a, b in r["not_kept"]))
                if "second" in r:
                    fitted = ", ".join(f"{k} {v:.4g}" for k, v in r["fitted"].items())
                    print(f"  3. with the drafts: {r['second']}; drafts fitted: {fitted or '-'}")
                print(f"  wall {' + '.join(f'{t:.0f}' for t in r['seconds'])} s", flush=True)


if __name__ == "__main__":
    main()
