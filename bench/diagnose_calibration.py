"""The confidence label calibrated leave-one-family-out: thresholds chosen on some truth
families, the label's reliability reported on the one held out.

    python bench/diagnose_calibration.py [--results runs/lofo] [--families pnp_fd,lab,perturbed]
        [--seeds 0] [--held-out pnp_fd]

Reads the diagnoses ``bench/diagnose_lofo.py`` cached under ``--results`` (run it first; the
label's thresholds do not change what is picked, so they are tried on the features each pick
recorded in ``diagnosis.json``: ``verdict.chain[].confidence_features``,
:mod:`physics.diagnose.confidence`).  For each family in turn: the thresholds that give the
most right "high" picks on the *other* families with none wrong (ties: the most demanding) are
chosen from a grid around the package's, and every pick of the held-out family is labelled
with them.  Printed: the thresholds of each fold, the reliability per label on each held-out
family (picks, right, acceptable — a near twin's relative — and wrong), the same with the
package's thresholds, and the pooled held-out table.
"""
from __future__ import annotations

import argparse
import itertools
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

#: The grid (names of :func:`physics.diagnose.confidence.thresholds`).
GRID = {"change_high_noise_floors": (1.5, 2.0, 3.0, 5.0, 8.0),
        "left_high_noise_floors": (1.5, 2.0, 3.0, 5.0, 10.0, 1e9),
        "twin_high_share": (1.0 / 3.0, 0.5, 0.6, 0.8, 0.95),
        "records_high_share": (0.5, 0.75, 1.0),
        "left_low_noise_floors": (5.0, 10.0, 15.0, 20.0, 30.0, 1e9)}


def picks(results: Path, selection) -> list[dict]:
    """Every pick of every cached case: family, truth, seed, effect, answer, features."""
    from bench.diagnose_lofo import case_dir
    from physics.diagnose.confidence import Confidence
    out = []
    for fam, truth, seed in selection:
        d = case_dir(results, fam, truth, seed)
        try:
            meta = json.loads((d / "meta.json").read_text())
            diag = json.loads((d / "diagnose" / "diagnosis.json").read_text())
        except (OSError, ValueError):
            continue
        exp, acc = set(meta["expected"]), set(meta["acceptable"])
        v, noise = diag["verdict"], diag.get("noise_floor_m")
        for p in v.get("chain") or []:
            f = p.get("confidence_features")
            if not f:
                continue
            if f.get("chain_left_noise_floors") is None and v.get("final_rmse_m") and noise:
                # recorded before the chain's end entered the features: the same number, from the verdict
                f = {**f, "chain_left_noise_floors": v["final_rmse_m"] / noise}
            if "undetermined_parameters" not in f:
                f = {**f, "undetermined_parameters": _undetermined(p.get("quality_flags") or [])}
            ans = "right" if p["effect"] in exp else ("acceptable" if p["effect"] in acc else "wrong")
            out.append({"family": fam, "truth": truth, "seed": seed, "effect": p["effect"], "answer": ans,
                        "features": Confidence.from_dict(f), "label_as_run": p.get("confidence_label")})
    return out


def _undetermined(flags: list[str]) -> int:
    """Own parameters inside their range and not determined, read from a pick's quality flags
    (:func:`physics.diagnose.verdict.quality`: recorded before they entered the features)."""
    loose = {f.split(" is not determined")[0] for f in flags if " is not determined" in f}
    bound = {f.split(" = ")[0] for f in flags if " is on a bound" in f}
    return len(loose - bound)


def labelled(ps: list[dict], th: dict | None) -> list[tuple[str, str]]:
    from physics.diagnose.confidence import label
    return [(label(p["features"], th).label, p["answer"]) for p in ps]


def table(rows: list[tuple[str, str]]) -> dict:
    t = {lab: {"n": 0, "right": 0, "acceptable": 0, "wrong": 0} for lab in ("high", "medium", "low")}
    for lab, ans in rows:
        t[lab]["n"] += 1
        t[lab][ans] += 1
    return t


def choose(ps: list[dict]) -> dict:
    """The grid point with the most right "high" picks and no wrong one on ``ps`` (ties: the
    most demanding thresholds), and among those the one with the most wrong "low" picks less
    right or acceptable ones (ties: the largest ``left_low_noise_floors``, which turns the fewest
    picks "low"; the "low" rules do not touch "high")."""
    best, key = None, None
    names = list(GRID)
    for combo in itertools.product(*(GRID[n] for n in names)):
        th = dict(zip(names, combo))
        rows = labelled(ps, th)
        wrong = sum(1 for lab, a in rows if lab == "high" and a == "wrong")
        right = sum(1 for lab, a in rows if lab == "high" and a != "wrong")
        low = sum(1 if a == "wrong" else -1 for lab, a in rows if lab == "low")
        k = (wrong == 0, right, low, th["change_high_noise_floors"], -th["left_high_noise_floors"],
             th["twin_high_share"], th["records_high_share"], th["left_low_noise_floors"])
        if key is None or k > key:
            best, key = th, k
    return best


def show(name: str, t: dict) -> None:
    print(f"  {name}")
    print(f"    {'label':7s} {'picks':>5s} {'right':>6s} {'accept.':>7s} {'wrong':>6s} {'right or acceptable':>20s}")
    for lab, x in t.items():
        n = x["n"]
        share = f"{100 * (x['right'] + x['acceptable']) / n:.0f} %" if n else "–"
        print(f"    {lab:7s} {n:5d} {x['right']:6d} {x['acceptable']:7d} {x['wrong']:6d} {share:>20s}")


def main(argv=None) -> int:
    from bench.diagnose_lofo import parse_seeds, selection
    from physics.diagnose.confidence import thresholds
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--results", default="runs/lofo")
    ap.add_argument("--families", default="pnp_fd,lab,perturbed")
    ap.add_argument("--truths", default="all")
    ap.add_argument("--seeds", default="0")
    ap.add_argument("--held-out", default="pnp_fd", help="the family whose fold gives the package's thresholds")
    args = ap.parse_args(argv)
    fams = [f for f in args.families.split(",") if f]
    ps = picks(Path(args.results), selection(fams, args.truths, parse_seeds(args.seeds)))
    print(f"{len(ps)} picks in {len({(p['family'], p['truth'], p['seed']) for p in ps})} cases")
    pooled, pooled_pkg = [], []
    for held in fams:
        train = [p for p in ps if p["family"] != held]
        test = [p for p in ps if p["family"] == held]
        if not test:
            continue
        th = choose(train) if train else thresholds()
        print(f"\nheld out {held}: thresholds chosen on {', '.join(f for f in fams if f != held)} "
              f"({len(train)} picks): " + ", ".join(f"{k} {v:.3g}" for k, v in th.items()))
        rows = labelled(test, th)
        pooled += rows
        show(f"{held} with the thresholds chosen without it", table(rows))
        pkg = labelled(test, None)
        pooled_pkg += pkg
        show(f"{held} with the package's thresholds", table(pkg))
        for p, (lab, _) in zip(test, rows):
            print(f"      {p['truth']:20s} s{p['seed']} {p['effect']:22s} {p['answer']:10s} {lab:6s} "
                  f"(change {p['features'].change:.3g}, left {p['features'].left:.3g}, twin {p['features'].twin:.2f}, "
                  f"records {p['features'].records:.2f}, flags {p['features'].flags}, held {p['features'].held:.2f}, "
                  f"chain left {p['features'].chain_left:.3g})")
    print()
    show("all folds pooled (each family labelled with thresholds chosen without it)", table(pooled))
    show("all families with the package's thresholds", table(pooled_pkg))
    print("\nthe package's thresholds: " + ", ".join(f"{k} {v:.3g}" for k, v in thresholds().items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
