"""Speed of the draft rounds of ``eap diagnose``: every least-squares start run to convergence
against the screened starts the command uses (:data:`physics.diagnose.draft.DRAFT_KEEP_STARTS`).

The diagnosis runs once; its draft rounds (:func:`physics.diagnose.draft.draft_effects` with the
command's :func:`~physics.diagnose.draft.rediagnosis`) then run twice, one process, in the same
run: with ``keep_starts=None`` (the reference) and with the command's screening.  Printed per
variant: the wall time of the rounds, the FRF evaluations they spent (model responses; the time
simulations are not counted), the drafts kept and the RMS error of the best model; then the
ratios.  The drafts kept and the error should agree (exit status 1 when the drafts differ).

    python bench/draft_speed.py [--kind creep] [--seed 0]     # a generated strip
    python bench/draft_speed.py RECORDS... --device ipmc_pt_eg --param L_total=29mm ...

Without records the case is :func:`physics.testbeds.demo.outside_catalog_case` ``--kind``
(default ``creep``, 40 s records at 200 Hz), diagnosed with ``--effects none`` (records given:
the device's default effects, as ``eap diagnose``).  The machine may be shared: compare the two
variants of one run, not runs.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
import warnings
from pathlib import Path

from nnmodel.app.cli import parse_quantity
from physics.device import load_device
from physics.diagnose import diagnose
from physics.diagnose.draft import DRAFT_KEEP_STARTS, draft_effects, rediagnosis
from physics.identify import FitOptions
from physics.identify.problem import IdentificationProblem
from physics.io.timeseries import write_timeseries
from physics.testbeds.demo import OUTSIDE, outside_catalog_case


def _records(args, tmp: Path) -> list[str]:
    if args.records:
        return list(args.records)
    ms, _ = outside_catalog_case(args.kind, args.seed, fs=200.0, duration=40.0)
    return [str(write_timeseries(m, tmp / f"{m.source}.csv")) for m in ms]


def _counting():
    """Count the model evaluations of every identification problem (the FRF residuals)."""
    count = [0]
    original = IdentificationProblem.responses

    def responses(self, theta):
        count[0] += 1
        return original(self, theta)
    IdentificationProblem.responses = responses
    return count


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("records", nargs="*", help="time-series records (default: a generated low-pass strip)")
    ap.add_argument("--device", default="ipmc_pt_eg")
    ap.add_argument("--param", action="append", default=[], help="NAME=VALUE with a unit, as eap diagnose")
    ap.add_argument("--effects", default=None, help="the model's effects (default: none for the generated "
                    "strip, default for records)")
    ap.add_argument("--kind", default="creep", choices=OUTSIDE, help="the generated strip's out-of-catalog physics")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    dev = load_device(args.device)
    if args.param:
        dev = dev.with_params(**dict(parse_quantity(item) for item in args.param))
    with tempfile.TemporaryDirectory() as tmp:
        files = _records(args, Path(tmp))
        opts = FitOptions()
        t0 = time.perf_counter()
        effects = args.effects or ("default" if args.records else "none")
        res = diagnose(files, dev, effects, options=opts)
        print(f"{len(files)} records; diagnosis {time.perf_counter() - t0:.1f} s: {res.verdict.status}, "
              f"final model {1e6 * res.final.rmse:.4g} µm")
        count = _counting()
        rows = []
        variants = (("every start to convergence", None), (f"screened, {DRAFT_KEEP_STARTS} kept", DRAFT_KEEP_STARTS))
        for label, keep in variants:
            n0, t0 = count[0], time.perf_counter()
            out = draft_effects(res, rediagnosis(files, res, opts, keep_starts=keep))
            wall = time.perf_counter() - t0
            kept = [d.effect_id for d in out.kept]
            rows.append((wall, count[0] - n0, kept, out.rmse_after))
            print(f"  {label:28s} {wall:7.1f} s  {count[0] - n0:8d} FRF evaluations  kept {kept or '–'}  "
                  f"best model {1e6 * out.rmse_after:.4g} µm")
    (w0, n0, k0, e0), (w1, n1, k1, e1) = rows
    print(f"screened / reference: wall {w1 / w0:.2f}×, evaluations {n1 / max(n0, 1):.2f}×; same drafts kept: "
          f"{k0 == k1}; best model error {1e6 * e1:.4g} vs {1e6 * e0:.4g} µm")
    return 0 if k0 == k1 else 1


if __name__ == "__main__":
    sys.exit(main())
