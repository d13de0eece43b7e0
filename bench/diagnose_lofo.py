"""The diagnosis judged family by family: ``eap diagnose`` run as a user runs it on the records
of each truth family (:mod:`bench.truths`), and what a leave-one-family-out protocol reports.

    python bench/diagnose_lofo.py [--families pnp_fd,circuit_lab,lab,perturbed] [--truths all]
        [--seeds 0,1] [--jobs 2] [--results runs/lofo] [--held-out pnp_fd]
        [--calibration-features features.jsonl] [--report-only] [--rerun]

Each case (family, truth, seed) is written as records (CSV + YAML) and diagnosed by the command
line — ``eap diagnose RECORDS --device ipmc_pt_eg --param … --effects … --out …`` with default
options — in its own process; its ``diagnosis.json``, the command, exit status and wall time are
cached under ``--results/FAMILY/TRUTH/sSEED/`` and reused while the records and the command are
unchanged (``--rerun`` forces).  ``--truths`` takes names, or kinds (``kind:catalog``,
``kind:outside,kind:pair``), or ``all``.

Printed: (a) the case table — family × truth × seed: verdict status, chain with labels, the
error before → after, the true model's error (the truth without its noise, scored the same
way), and the judgement; (b) a reliability table per confidence label (how often picks labelled
"high", "medium", "low" were right, acceptable — a near twin's relative — or wrong; what
ambiguous and null answers were) on the held-out family and on every family in turn; (c) the
targets of issue 34 as PASS/FAIL lines.  Protocol: thresholds are chosen on all families but
one (``--calibration-features`` dumps every candidate's fields with the right answer for that)
and reported on the one held out.

What ``diagnosis.json`` holds is read in one place, :func:`extract`.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

LABELS = ("high", "medium", "low")
#: Targets (issue 34)
ERROR_RATIO, NAMED_SHARE, HIGH_SHARE, PAIR_SHARE, HIGH_RIGHT, OFFSET_TOL = 1.5, 5 / 6, 4 / 6, 5 / 6, 0.95, 10e-6
ROUTE_RATIO = 3.0
LAB_LIKE = ("circuit_lab", "lab")


# ============================================================================ reading diagnosis.json


def extract(diag: dict) -> dict:
    """What the protocol needs from a ``diagnosis.json`` — the one place that knows its layout:
    status, chain [(effect, label, weight, rmse before, rmse after)], ambiguous effects, base
    and final RMS [m] (final: after the verdict's chain; best: the best model the command wrote,
    drafts included — the end of the default route), noise floor [m], fitted offsets {record: m} and every evaluated
    candidate of every step (the JSON rows, with their step).  Missing fields read as None."""
    v = diag.get("verdict") or {}
    chain = []
    for p in v.get("chain") or []:
        label = p.get("confidence_label") or p.get("label")
        chain.append({"effect": p.get("effect"), "label": label, "weight": p.get("confidence"),
                      "rmse_before": p.get("rmse_before_m"), "rmse_after": p.get("rmse_after_m"),
                      "quality_flags": p.get("quality_flags") or []})
    base = (diag.get("base") or {}).get("rmse")
    # the model the verdict describes: the base with the chain's removals, refit and picks
    final = v.get("final_rmse_m") or (chain[-1]["rmse_after"] if chain else base)
    offsets = {}
    for r in (v.get("nuisance") or {}).get("records") or []:
        if r.get("offset_um") is not None:
            offsets[Path(str(r.get("record"))).stem] = 1e-6 * float(r["offset_um"])
    cands = []
    for s in diag.get("steps") or []:
        for row in s.get("ranking") or []:
            cands.append({**row, "step": s.get("step"), "picked": row.get("effect") == s.get("picked"),
                          "step_base_rmse": s.get("base_rmse"), "weight_of_base": s.get("weight_of_base")})
    best = (diag.get("best_model") or {}).get("rmse_m")
    return {"status": v.get("status"), "chain": chain, "ambiguous": list(v.get("ambiguous") or []),
            "base_rmse": base, "final_rmse": final, "best_rmse": best if best is not None else final, "noise_floor": diag.get("noise_floor_m"), "offsets": offsets,
            "candidates": cands, "remaining_kind": v.get("remaining_kind"),
            "wall_s": (diag.get("timings_s") or {}).get("total")}


# ============================================================================ judging one case


def judge(meta: dict, x: dict | None) -> dict:
    """The judgement of one case against its truth (``meta`` from the case's ``describe``)."""
    exp, acc = set(meta["expected"]), set(meta["acceptable"])
    if x is None:
        return {"exit_error": True, "right": False, "picks": [], "named": False, "wrong_high": False,
                "ratio": None, "best_ratio": None, "offset_err": None}

    def verdict_of(e):
        return "right" if e in exp else ("acceptable" if e in acc else "wrong")

    picks = [(p["effect"], p["label"], verdict_of(p["effect"])) for p in x["chain"]]
    named = exp <= {p[0] for p in picks} if exp else False
    wrong = [p for p in picks if p[2] == "wrong"]
    wrong_high = any(p[1] == "high" for p in wrong)
    true_e = meta["true_error_m"]
    ratio = (x["final_rmse"] / true_e) if (x["final_rmse"] and true_e) else None
    best_ratio = (x["best_rmse"] / true_e) if (x.get("best_rmse") and true_e) else ratio
    off_err = None
    if x["offsets"]:
        errs = [abs(x["offsets"][k] - v[1]) for k, v in meta["true_offsets_m"].items() if k in x["offsets"]]
        off_err = max(errs) if errs else None
    if meta["expected"]:
        right = named and not wrong
    elif meta["kind"] == "route":            # the default route: the best model it writes is what counts
        right = not wrong and best_ratio is not None and best_ratio <= ROUTE_RATIO
    else:
        right = not wrong
    return {"exit_error": False, "right": right, "picks": picks, "named": named, "wrong": bool(wrong),
            "wrong_high": wrong_high, "ratio": ratio, "best_ratio": best_ratio,
            "offset_err": off_err,
            "high_on_expected": any(p[1] == "high" and p[2] == "right" for p in picks)}


# ============================================================================ running


def case_dir(results: Path, family: str, truth: str, seed: int) -> Path:
    return results / family / truth / f"s{seed}"


def _hash_files(files) -> str:
    h = hashlib.sha256()
    for f in sorted(files):
        h.update(Path(f).name.encode())
        h.update(Path(f).read_bytes())
    return h.hexdigest()


def prepare(results: Path, family: str, truth: str, seed: int) -> tuple[dict, list[str], bool]:
    """Write the case's records (if changed) and say whether its cached diagnosis still holds."""
    from bench.truths import make_case
    d = case_dir(results, family, truth, seed)
    rec = d / "records"
    t0 = time.perf_counter()
    case = make_case(family, truth, seed)
    gen_s = time.perf_counter() - t0
    tmp = d / "records.new"
    if tmp.exists():
        for f in tmp.iterdir():
            f.unlink()
    files = case.write(tmp)
    sidecars = sorted(p for p in tmp.iterdir() if p.suffix == ".yaml")
    digest = _hash_files(list(files) + sidecars)
    meta = case.describe()
    meta.update({"generation_s": gen_s, "records_sha256": digest})
    old = _read_json(d / "meta.json")
    if old and old.get("records_sha256") == digest and rec.exists():
        for f in tmp.iterdir():
            f.unlink()
        tmp.rmdir()
    else:
        if rec.exists():
            for f in rec.iterdir():
                f.unlink()
            rec.rmdir()
        tmp.rename(rec)
    csvs = sorted(str(p) for p in rec.glob("*.csv"))
    cmd = [sys.executable, "-m", "nnmodel.app.cli", "diagnose", *csvs, "--device", case.device, *case.param_args(),
           "--effects", case.effects, "--out", str(d / "diagnose"), "--quiet"]
    meta["command"] = ["eap"] + cmd[3:]
    fresh = bool(old and old.get("records_sha256") == digest and old.get("command") == meta["command"]
                 and "rc" in old)
    if fresh:
        meta.update({k: old[k] for k in ("rc", "wall_s", "stderr_tail", "code") if k in old})
    return meta, cmd, fresh


def run_case(results: Path, family: str, truth: str, seed: int, rerun: bool, timeout: float) -> dict:
    meta, cmd, fresh = prepare(results, family, truth, seed)
    d = case_dir(results, family, truth, seed)
    if fresh and not rerun:
        meta["cached"] = True
        return meta
    out = d / "diagnose"
    if out.exists():
        import shutil
        shutil.rmtree(out)
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    t0 = time.perf_counter()
    try:
        p = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=timeout)
        rc, err, so = p.returncode, p.stderr, p.stdout
    except subprocess.TimeoutExpired as exc:
        rc, err, so = 124, f"timed out after {timeout:.0f} s", (exc.stdout or b"").decode() if isinstance(
            exc.stdout, bytes) else (exc.stdout or "")
    meta.update({"rc": rc, "wall_s": time.perf_counter() - t0, "stderr_tail": (err or "")[-2000:],
                 "stdout_tail": (so or "")[-3000:], "code": _code_rev(), "cached": False})
    _write_json(d / "meta.json", meta)
    return meta


def _code_rev() -> str:
    try:
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout
        dirty = subprocess.run(["git", "status", "--porcelain", "physics", "nnmodel"], cwd=ROOT, capture_output=True,
                               text=True).stdout
        return rev.strip() + ("+dirty" if dirty.strip() else "")
    except OSError:
        return "?"


def _read_json(p: Path):
    try:
        return json.loads(p.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def _write_json(p: Path, obj) -> None:
    tmp = p.with_name(p.name + ".part")
    tmp.write_text(json.dumps(obj, indent=1, default=float), encoding="utf-8")
    tmp.replace(p)


# ============================================================================ collecting


def collect(results: Path, selection) -> list[dict]:
    """Every selected case with a cached run: meta, extraction and judgement."""
    rows = []
    for family, truth, seed in selection:
        d = case_dir(results, family, truth, seed)
        meta = _read_json(d / "meta.json")
        if not meta or "rc" not in meta:
            continue
        diag = _read_json(d / "diagnose" / "diagnosis.json") if meta["rc"] == 0 else None
        x = extract(diag) if diag else None
        rows.append({"meta": meta, "x": x, "j": judge(meta, x)})
    return rows


def _um(v) -> str:
    return "–" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{1e6 * v:.3g}"


def print_cases(rows: list[dict]) -> None:
    print("\n(a) cases: family × truth × seed — verdict, chain [label], RMS error before → after [µm], "
          "true model's error [µm], final/true, best model written (drafts included)/true, judgement")
    print(f"{'family':11s} {'truth':19s} {'s':>2s} {'kind':8s} {'status':30s} {'chain [label]':44s} "
          f"{'before→after':>15s} {'true':>6s} {'ratio':>6s} {'best':>6s} {'judgement':10s} {'wall':>5s}")
    for r in rows:
        m, x, j = r["meta"], r["x"], r["j"]
        if x is None:
            print(f"{m['family']:11s} {m['truth']:19s} {m['seed']:2d} {m['kind']:8s} "
                  f"ERROR EXIT rc={m['rc']}: {m.get('stderr_tail', '').strip().splitlines()[-1:] }")
            continue
        chain = " ".join(f"{p[0]}[{p[1]}]" for p in j["picks"]) or (
            "ambiguous " + "/".join(x["ambiguous"]) if x["ambiguous"] else "–")
        if x["ambiguous"] and j["picks"]:
            chain += " (amb " + "/".join(x["ambiguous"]) + ")"
        mark = "right" if j["right"] else ("WRONG-HIGH" if j["wrong_high"] else "wrong")
        ratio = f"{j['ratio']:.2f}" if j["ratio"] else "–"
        best = f"{j['best_ratio']:.2f}" if j.get("best_ratio") else "–"
        print(f"{m['family']:11s} {m['truth']:19s} {m['seed']:2d} {m['kind']:8s} {str(x['status'])[:30]:30s} "
              f"{chain[:44]:44s} {_um(x['base_rmse']):>7s}→{_um(x['final_rmse']):<7s} {_um(m['true_error_m']):>6s} "
              f"{ratio:>6s} {best:>6s} {mark:10s} {m.get('wall_s', 0):5.0f}")


def reliability(rows: list[dict]) -> dict:
    """Per label: picks, right, acceptable, wrong; ambiguous and null answers (module doc)."""
    tab = {lab: {"n": 0, "right": 0, "acceptable": 0, "wrong": 0} for lab in LABELS}
    amb = {"n": 0, "holds_expected": 0, "expected_nothing": 0}
    null = {"n": 0, "right": 0}
    for r in rows:
        x, j, m = r["x"], r["j"], r["meta"]
        if x is None:
            continue
        for eff, lab, v in j["picks"]:
            t = tab.setdefault(lab or "?", {"n": 0, "right": 0, "acceptable": 0, "wrong": 0})
            t["n"] += 1
            t[v] += 1
        if not j["picks"]:
            if x["ambiguous"]:
                amb["n"] += 1
                amb["holds_expected"] += bool(set(m["expected"]) & set(x["ambiguous"]))
                amb["expected_nothing"] += not m["expected"]
            else:
                null["n"] += 1
                null["right"] += not m["expected"]
    return {"labels": tab, "ambiguous": amb, "null": null}


def print_reliability(name: str, rel: dict) -> None:
    print(f"\n(b) reliability per label — {name}")
    print(f"  {'label':8s} {'picks':>5s} {'right':>6s} {'accept.':>7s} {'wrong':>6s} {'right %':>8s} {'not wrong %':>11s}")
    for lab, t in rel["labels"].items():
        n = t["n"]
        pr = f"{100 * t['right'] / n:.0f} %" if n else "–"
        pn = f"{100 * (t['right'] + t['acceptable']) / n:.0f} %" if n else "–"
        print(f"  {lab:8s} {n:5d} {t['right']:6d} {t['acceptable']:7d} {t['wrong']:6d} {pr:>8s} {pn:>11s}")
    a, nl = rel["ambiguous"], rel["null"]
    print(f"  ambiguous answers: {a['n']} (the expected effect among them: {a['holds_expected']}; nothing was "
          f"expected: {a['expected_nothing']})")
    print(f"  null answers (no effect named): {nl['n']}, right (nothing was expected) {nl['right']}")


def targets(rows: list[dict], name: str) -> list[tuple[str, bool | None, str]]:
    """The issue's targets on ``rows`` as (line, pass?, detail)."""
    ok = [r for r in rows if r["x"] is not None]
    out = []
    quiet = [r for r in rows if r["meta"]["kind"] in ("none", "outside", "twin")]
    wh = [r for r in quiet if r["j"]["wrong_high"]]
    out.append(("no wrong 'high' on out-of-catalog, near twins, nothing hidden", not wh if quiet else None,
                f"{len(wh)} wrong high in {len(quiet)} cases"
                + (": " + ", ".join(f"{r['meta']['family']}/{r['meta']['truth']}/s{r['meta']['seed']}" for r in wh)
                   if wh else "")))
    cat = [r for r in rows if r["meta"]["kind"] == "catalog"]
    if cat:
        named = [r for r in cat if r["j"]["named"] and r["j"]["ratio"] is not None and r["j"]["ratio"] <= ERROR_RATIO]
        best = [r for r in cat if r["j"]["named"] and r["j"]["best_ratio"] is not None
                and r["j"]["best_ratio"] <= ERROR_RATIO]
        high = [r for r in cat if r["j"].get("high_on_expected")]
        out.append((f"in-catalog named within {ERROR_RATIO}× true error ≥ 5/6", len(named) >= NAMED_SHARE * len(cat),
                    f"{len(named)}/{len(cat)} after the verdict's chain (the best model written, drafts included: "
                    f"{len(best)}/{len(cat)})"))
        out.append(("in-catalog right pick labelled 'high' ≥ 4/6", len(high) >= HIGH_SHARE * len(cat),
                    f"{len(high)}/{len(cat)}"))
    hp = [p for r in ok for p in r["j"]["picks"] if p[1] == "high"]
    if hp:
        right = sum(p[2] != "wrong" for p in hp)
        out.append(("'high' picks right (or a twin's relative) ≥ 95 %", right >= HIGH_RIGHT * len(hp),
                    f"{right}/{len(hp)}"))
    else:
        out.append(("'high' picks right ≥ 95 %", None, "no 'high' pick"))
    pairs = [r for r in rows if r["meta"]["kind"] == "pair"]
    if pairs:
        both = [r for r in pairs if r["j"]["named"]]
        err = [r for r in pairs if r["x"] is None]
        out.append(("pairs: both named ≥ 5/6, no error exit", len(both) >= PAIR_SHARE * len(pairs) and not err,
                    f"both named {len(both)}/{len(pairs)}, error exits {len(err)}"))
    route = [r for r in rows if r["meta"]["kind"] == "route"]
    if route:
        good = [r for r in route if r["j"]["best_ratio"] is not None and r["j"]["best_ratio"] <= ROUTE_RATIO]
        out.append((f"default route on creep + RH dependence: best model written ≤ {ROUTE_RATIO:g}× true",
                    len(good) == len(route),
                    "; ".join(f"{r['meta']['family']}/s{r['meta']['seed']}: best model "
                              f"{r['j']['best_ratio'] and round(r['j']['best_ratio'], 2)}× (after the verdict's chain "
                              f"{r['j']['ratio'] and round(r['j']['ratio'], 2)}×)" for r in route)))
    slow = [r for r in rows
            if r["meta"]["family"] in LAB_LIKE and r["meta"]["slow"] and r["meta"]["kind"] == "catalog"]
    if slow:
        good = [r for r in slow if r["j"]["named"] and r["j"]["ratio"] is not None and r["j"]["ratio"] <= ERROR_RATIO
                and r["j"]["offset_err"] is not None and r["j"]["offset_err"] <= OFFSET_TOL]
        detail = "; ".join(f"{r['meta']['family']}/{r['meta']['truth']}/s{r['meta']['seed']}: named "
                           f"{r['j']['named']}, ratio {r['j']['ratio'] and round(r['j']['ratio'], 2)} (best model written "
                           f"{r['j']['best_ratio'] and round(r['j']['best_ratio'], 2)}), offset error "
                           f"{_um(r['j']['offset_err'])} µm" for r in slow)
        out.append(("lab-like slow physics: named, ≤ 1.5× true, offsets within ±10 µm", len(good) == len(slow),
                    f"{len(good)}/{len(slow)} ({detail})"))
    return out


def print_targets(rows, name) -> None:
    print(f"\n(c) targets — {name}")
    for line, passed, detail in targets(rows, name):
        mark = "n/a " if passed is None else ("PASS" if passed else "FAIL")
        print(f"  {mark}  {line}: {detail}")


def dump_features(rows: list[dict], path: Path) -> None:
    """One JSON line per case: the truth and its answer, and every candidate's fields as written
    in diagnosis.json with its judgement (right / acceptable / wrong)."""
    with open(path, "w", encoding="utf-8") as fh:
        for r in rows:
            m, x = r["meta"], r["x"]
            exp, acc = set(m["expected"]), set(m["acceptable"])
            rec = {k: m[k] for k in ("family", "truth", "kind", "seed", "expected", "acceptable", "true_error_m",
                                     "noise_floor_m", "true_offsets_m", "effects", "rc")}
            if x is not None:
                rec.update({"status": x["status"], "chain": x["chain"], "ambiguous": x["ambiguous"],
                            "base_rmse_m": x["base_rmse"], "final_rmse_m": x["final_rmse"],
                            "noise_floor_estimated_m": x["noise_floor"], "offsets_m": x["offsets"],
                            "candidates": [{**c, "answer": "right" if c.get("effect") in exp else
                                            ("acceptable" if c.get("effect") in acc else "wrong")}
                                           for c in x["candidates"]]})
            fh.write(json.dumps(rec, default=float) + "\n")
    print(f"\nwrote {len(rows)} cases' candidate features to {path}")


# ============================================================================ main


def selection(families, truths_arg: str, seeds) -> list[tuple[str, str, int]]:
    from bench.truths import truth, truths
    out = []
    for fam in families:
        allt = truths(fam)
        if truths_arg == "all":
            sel = allt
        else:
            sel = []
            for item in truths_arg.split(","):
                if item.startswith("kind:"):
                    sel += [t for t in allt if truth(fam, t).kind == item[5:] and t not in sel]
                elif item in allt and item not in sel:
                    sel.append(item)
        out += [(fam, t, s) for t in sel for s in seeds]
    return out


def parse_seeds(text: str) -> list[int]:
    out = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b) + 1)) if b else [int(a)]
    return out


def main(argv=None) -> int:
    from bench.truths import FAMILIES
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--families", default=",".join(FAMILIES))
    ap.add_argument("--truths", default="all",
                    help="names, kind:KIND (none, catalog, outside, twin, pair, route) or all")
    ap.add_argument("--seeds", default="0,1", help="comma-separated seeds and ranges: 0,1 or 0-3")
    ap.add_argument("--jobs", type=int, default=1, help="diagnoses run in parallel (at most 2 on a shared machine)")
    ap.add_argument("--results", default="runs/lofo", help="cache folder of the cases and their diagnoses")
    ap.add_argument("--held-out", default="pnp_fd", help="the family reported as held out")
    ap.add_argument("--calibration-features", default=None, metavar="FILE.jsonl")
    ap.add_argument("--report-only", action="store_true", help="no new runs: report what is cached")
    ap.add_argument("--rerun", action="store_true", help="run again even when the cache holds")
    ap.add_argument("--timeout", type=float, default=900.0, help="seconds per diagnosis")
    args = ap.parse_args(argv)
    families = [f for f in args.families.split(",") if f]
    for f in families:
        if f not in FAMILIES:
            ap.error(f"--families: {f!r} is not one of {', '.join(FAMILIES)}")
    seeds = parse_seeds(args.seeds)
    sel = selection(families, args.truths, seeds)
    results = Path(args.results)
    results.mkdir(parents=True, exist_ok=True)
    if not args.report_only:
        print(f"{len(sel)} cases, {args.jobs} at a time, cache {results}", flush=True)

        def one(item):
            fam, tr, sd = item
            try:
                m = run_case(results, fam, tr, sd, args.rerun, args.timeout)
            except Exception as exc:            # a case that cannot be generated is reported, not fatal
                print(f"  FAILED {fam}/{tr}/s{sd}: {type(exc).__name__}: {exc}", flush=True)
                return None
            print(f"  {'cached' if m.get('cached') else 'ran   '} {fam}/{tr}/s{sd}: rc {m['rc']}, "
                  f"{m.get('wall_s', 0):.0f} s", flush=True)
            return m

        with ThreadPoolExecutor(max_workers=max(1, args.jobs)) as ex:
            list(ex.map(one, sel))
    rows = collect(results, sel)
    print_cases(rows)
    present = [f for f in families if any(r["meta"]["family"] == f for r in rows)]
    if args.held_out in present:
        held = [r for r in rows if r["meta"]["family"] == args.held_out]
        print_reliability(f"held-out family {args.held_out}", reliability(held))
        print_targets(held, f"held-out family {args.held_out}")
    for f in present:
        if f == args.held_out:
            continue
        fr = [r for r in rows if r["meta"]["family"] == f]
        print_reliability(f"family {f}", reliability(fr))
        print_targets(fr, f"family {f}")
    print_reliability("all families", reliability(rows))
    print_targets(rows, "all families")
    walls = [r["meta"].get("wall_s", 0) for r in rows]
    if walls:
        print(f"\n{len(rows)} cases; wall per diagnosis (command, incl. start-up) median "
              f"{sorted(walls)[len(walls) // 2]:.0f} s, max {max(walls):.0f} s (shared, loaded 2-core machine)")
    if args.calibration_features:
        dump_features(rows, Path(args.calibration_features))
    return 0


if __name__ == "__main__":
    sys.exit(main())
