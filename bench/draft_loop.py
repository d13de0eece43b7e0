"""The out-of-catalog loop from the command line, per truth and seed: diagnosis → drafted
effects → diagnosis again with the drafts → the error before and after, against the true
model's error.

    python bench/draft_loop.py [--kinds lowpass,drift,creep] [--seeds 0,1,2] [--suite lab|sim]

Records: :func:`physics.diagnose.demo.outside_catalog_case` (a sweep 0.1–50 Hz and a 20 s
pulse, 60 s at 200 Hz; the user's model is the bare device), written as CSV files and read
back by ``eap diagnose`` as a user would: ``lab`` exports them as an instrument does (tip in
mm, 3 µm noise, an offset, a random-walk drift, hygrometer jitter, no excitation or sensor
metadata), ``sim`` as the simulator writes them (metadata kept).  For each case it prints the
truth, the first diagnosis (status, pick, RMS error of its final model), the kept drafts with
their fitted parameters, whether each passed the contract check, the second diagnosis with
the drafts passed back (``--effects-path``), and the true model's error (measurement minus
the true deflection, each record's mean removed, full rate).  The machine may be shared:
the wall times are indicative.
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
    from nnmodel.cli import main
    out = io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        code = main(argv)
    if code != 0:
        raise SystemExit(f"eap {' '.join(argv)} failed ({code}):\n{out.getvalue()}")
    return out.getvalue(), time.perf_counter() - t0


def _verdict(d: dict) -> str:
    """Status, pick (or the ambiguous ones) with their RMS error [µm] and confidence label."""
    v = d["verdict"]
    rmse = {r["effect"]: r.get("rmse_after") for r in d["ranking"]}
    picks = [v["missing_effect"]] if v.get("missing_effect") else list(v.get("ambiguous") or [])
    named = " / ".join(f"{p} {_um(rmse.get(p))}" for p in picks) or f"no pick, base {_um(d['base']['rmse'])}"
    return f"{named} ({v['status']}" + (f", {v.get('confidence_label')})" if v.get("missing_effect") else ")")


def case(kind: str, seed: int, suite: str, tmp: Path) -> dict:
    from physics.diagnose.demo import outside_catalog_case
    from physics.effects import EFFECTS, unregister
    from physics.timeseries import write_timeseries
    ms, tp, clean = outside_catalog_case(kind, seed, fs=200.0, duration=60.0, lab=suite == "lab", clean=True)
    files, sq, n = [], 0.0, 0
    for m, y in zip(ms, clean):
        files.append(str(write_timeseries(m, tmp / f"{m.source}.csv",
                                          units={"deflection": "mm"} if suite == "lab" else {})))
        e = m.deflection - y
        e = e - e.mean()
        sq, n = sq + float(e @ e), n + e.size
    out, t1 = _run(["diagnose", *files, "--effects", "none", "--out", str(tmp / "dx"), "--quiet",
                    "--draft-effects", str(tmp / "drafts")])
    first = json.loads((tmp / "dx" / "diagnosis.json").read_text())
    drafts = sorted((tmp / "drafts").glob("*.py")) if (tmp / "drafts").is_dir() else []
    checks = dict(re.findall(r"draft: \S*?(\w+\.py): contract check (passed|FAILED)", out))
    row = {"kind": kind, "seed": seed, "truth": tp, "true_error_m": math.sqrt(sq / n),
           "noise_floor_m": first.get("noise_floor_m"), "base_m": first["base"]["rmse"],
           "first": _verdict(first),
           "drafts": {p.name: checks.get(p.name, "?") for p in drafts}, "seconds": [t1]}
    if drafts:
        argv = ["diagnose", *files, "--effects", "none", "--out", str(tmp / "dx2"), "--quiet"]
        for p in drafts:
            argv += ["--effects-path", str(p)]
        try:
            _, t2 = _run(argv)
        finally:
            for i in [i for i in EFFECTS if i.startswith("drafted_")]:
                unregister(i)
        second = json.loads((tmp / "dx2" / "diagnosis.json").read_text())
        fitted = {k: x for r in second["ranking"] if r["effect"].startswith("drafted_")
                  for k, x in r.get("effect_parameters", {}).items()}
        row.update({"second": _verdict(second), "fitted": fitted})
        row["seconds"].append(t2)
    return row


def _um(x) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{1e6 * x:.3g}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kinds", default="lowpass,drift,creep")
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--suite", default="lab", choices=("lab", "sim"))
    args = ap.parse_args()
    print(f"suite {args.suite}: error [µm] = RMS of the final model; true = the true model's error\n")
    for kind in args.kinds.split(","):
        for seed in (int(s) for s in args.seeds.split(",")):
            with tempfile.TemporaryDirectory(prefix="eap-draft-loop-") as tmp:
                r = case(kind, seed, args.suite, Path(tmp))
            truth = ", ".join(f"{k} {v:.4g}" for k, v in r["truth"].items())
            print(f"{kind} seed {seed} (truth: {truth})")
            print(f"  1. eap diagnose: base {_um(r['base_m'])} → {r['first']}; noise floor {_um(r['noise_floor_m'])}; "
                  f"true model {_um(r['true_error_m'])}")
            print("  2. drafts: " + (", ".join(f"{k} (contract {v})" for k, v in r["drafts"].items()) or "none"))
            if "second" in r:
                fitted = ", ".join(f"{k} {v:.4g}" for k, v in r["fitted"].items())
                print(f"  3. with the drafts (--effects-path): {r['second']}; drafts fitted: {fitted or '-'}")
            print(f"  wall {' + '.join(f'{t:.0f}' for t in r['seconds'])} s", flush=True)


if __name__ == "__main__":
    main()
