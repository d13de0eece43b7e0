"""``eap benchmark``: train and compare the neural models on a benchmark suite."""
from __future__ import annotations

from physics.errors import InputError

from ...benchmarks import SUITES, get_suite
from ._common import add_output_options, add_parallel_options, check_out, parallel_settings, writing

NAME = "benchmark"
#: argument destinations that name files or folders this command reads (never replaced by its outputs)
INPUTS = ("data",)
HELP = "compare FF / RBF / NARX / LSTM / GRU / hybrid on a benchmark suite (JSON + HTML + PNG report)"
DESCRIPTION = (HELP + ". Suites: " + "; ".join(f"{s.name}: {s.help}" for s in SUITES.values())
               + "; all: every suite, each into OUT/SUITE. Each model is trained with its recipe "
               "(configs/train/NAME.yaml) plus the suite's settings; --set overrides any hyper-parameter.")


def add_arguments(p):
    p.add_argument("--suite", required=True, choices=sorted(SUITES) + ["all"],
                   help="benchmark suite (all: every suite, each into OUT/SUITE)")
    add_output_options(p, None, "output folder for the report (and model bundles)")
    p.add_argument("--models", default=None,
                   help="comma-separated models; none = the suite's list (" + "; ".join(
                       f"{s.name}: {','.join(s.default_models)}" for s in SUITES.values()) + ")")
    p.add_argument("--quick", action="store_true", help="short training budgets (about a minute per model)")
    p.add_argument("--max-time", type=float, default=None,
                   help="wall-clock training budget per model [s] (overrides the suite and recipe)")
    p.add_argument("--set", action="append", default=[], metavar="MODEL.KEY=VALUE",
                   help="override one hyper-parameter, e.g. --set narx.poly_degree=1 (repeatable)")
    p.add_argument("--data", default=None,
                   help="suite data: silverbox: the SNLS80mV.csv file or its folder (default: $EAP_SILVERBOX; "
                        "the file is not shipped); eap: a dataset folder (default: generate the default dataset into OUT)")
    p.add_argument("--limit", type=int, default=None,
                   help="truncate every data part to this many samples (smoke tests only: "
                        "the figures are then not comparable)")
    add_parallel_options(p)
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.add_argument("--no-save-models", action="store_true", help="do not save model bundles")


def parse_sets(items, models) -> dict:
    """``--set MODEL.KEY=VALUE`` items (as train-compare reads them) for the models run."""
    from .train_compare import parse_overrides
    out = parse_overrides(items or [])
    bad = sorted(set(out) - set(models))
    if bad:
        raise InputError(f"--set: model {bad[0]!r} is not among the models run ({', '.join(models)})")
    return out


def run(args) -> int:
    from pathlib import Path

    if args.suite == "all":  # noqa: SIM102 (checked before any work)
        if args.data or args.limit is not None:
            raise InputError("--data and --limit belong to one suite; run the suites one by one to use them")
    inputs = [args.data] if args.data else []
    check_out(args, inputs)
    with writing(args, inputs) as tmp:
        if args.suite == "all":
            for name in SUITES:
                _run_suite(args, get_suite(name), str(tmp / name), lenient=True)
        else:
            _run_suite(args, get_suite(args.suite), str(tmp))
    print(f"benchmark results in {Path(args.out)}")
    return 0


def _run_suite(args, suite, out: str, lenient: bool = False) -> None:
    """Run one suite; ``lenient`` (``--suite all``): models and --set entries that a suite
    does not run are skipped instead of refused."""
    from ...benchmarks.common import parse_models

    models = parse_models(args.models, suite.default_models)
    if lenient and args.models:
        models = [m for m in models if m in suite.default_models] or list(suite.default_models)
    sets = [it for it in (args.set or []) if not lenient or it.split(".", 1)[0] in models]
    overrides = parse_sets(sets, models)
    if args.max_time is not None:
        if args.max_time <= 0:
            raise InputError(f"--max-time must be positive, got {args.max_time}")
        for m in models:
            overrides.setdefault(m, {}).setdefault("max_time", args.max_time)
    options = {}
    if args.data:
        options["data"] = args.data
    if args.limit is not None:
        if args.limit < 1:
            raise InputError(f"--limit must be a positive number of samples, got {args.limit}")
        options["limit"] = args.limit
    suite.load()(models, out, quick=args.quick, overrides=overrides,
                 progress=not args.no_progress, save_models=not args.no_save_models,
                 settings=parallel_settings(args), **options)
