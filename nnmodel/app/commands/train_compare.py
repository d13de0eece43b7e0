"""``eap train-compare``: train FF / RBF / NARX / LSTM (/GRU) on a dataset and compare them."""
from __future__ import annotations

from physics.errors import InputError
from physics.limits import MAX_TUNE_TRIALS, check_count
from physics.io.outputs import component
from physics.io.yamlio import loads_yaml

from ._common import add_output_options, add_parallel_options, parallel_settings

NAME = "train-compare"
#: argument destinations that name files or folders this command reads (never replaced by its outputs)
INPUTS = ("dataset", "physics")
HELP = "train neural models on a dataset and compare them (free run, held-out RH, physics reference)"
#: the built-ins that declare themselves defaults, for the help text only (the command line does not
#: import torch to print its help; a test holds it to :func:`nnmodel.models.default_kinds`)
DEFAULT_SET = "ff, rbf, narx, lstm, ss"


def add_arguments(p):
    p.add_argument("dataset", help="dataset folder (from `eap generate`)")
    p.add_argument("--models", default=None,
                   help=f"comma-separated: ff, rbf, narx, lstm, gru, ss, hybrid, or a network installed under the "
                        f"entry-point group eap.networks (default: the networks that declare themselves defaults, "
                        f"{DEFAULT_SET})")
    add_output_options(p, "runs/train-compare", "run folder (models/, compare.json, the page index.html)")
    p.add_argument("--set", action="append", default=[], metavar="MODEL.KEY=VALUE",
                   help="override a recipe hyper-parameter, e.g. --set narx.hidden=64 (repeatable)")
    p.add_argument("--max-time-s", type=float, default=None,
                   help="wall-clock guard per model [s] (default: the recipes'; budgets are epochs, the card says if it fired)")
    p.add_argument("--quiet", action="store_true", help="no progress output (the table is still printed)")
    p.add_argument("--devices", type=int, default=1,
                   help="processes (CPU) or GPUs that train each network together (Lightning)")
    p.add_argument("--strategy", default=None,
                   help="Lightning strategy for --devices > 1 (default: ddp_spawn, gloo on CPUs; ddp on GPUs)")
    p.add_argument("--tune", type=int, default=None, metavar="N",
                   help="search each model's settings (its recipe's tune section) with N trials scored on the "
                        "validation data (Optuna TPE, seeded; trials run on --workers/--scheduler), then train and "
                        "save the best")
    p.add_argument("--accelerator", choices=["auto", "cpu", "gpu"], default="auto",
                   help="where the networks train: auto = a GPU when torch sees one, else the CPU (the card records "
                        "the device; --set MODEL.accelerator=... wins for that model)")
    p.add_argument("--rh-tolerance", type=float, default=1.0,
                   help="the hygrometer's tolerance [%%]: test records whose RH differ by less form one RH level "
                        "(default 1, as eap diagnose)")
    add_parallel_options(p)
    p.add_argument("--physics", default=None, metavar="DEVICE_OR_YAML",
                   help="score this device's simulator beside the networks (default: the dataset's generator; "
                        "none for measured data)")


def parse_overrides(items) -> dict:
    out: dict[str, dict] = {}
    for it in items:
        if "=" not in it or "." not in it.split("=", 1)[0]:
            raise InputError(f"--set expects MODEL.KEY=VALUE, got {it!r}")
        key, val = it.split("=", 1)
        model, hp = (s.strip() for s in key.split(".", 1))
        if hp in out.get(model, {}):
            raise InputError(f"--set {model}.{hp} is given twice; give each setting once")
        out.setdefault(model, {})[hp] = _value(val)
    return out


def _value(text: str):
    """A number if it reads as one (YAML would keep '1e-3' a string), else YAML."""
    for cast in (int, float):
        try:
            return cast(text)
        except ValueError:
            pass
    return loads_yaml(text, f"--set value {text[:40]!r}", "value")


def run(args) -> int:
    from nnmodel.models import MODELS, default_kinds, load_plugins
    from nnmodel.traincompare import format_table, train_compare
    load_plugins()
    if args.models is None:
        args.models = ",".join(default_kinds())
    models = [m.strip() for m in args.models.split(",") if m.strip()]
    if not models:
        raise InputError(f"--models {args.models!r} names no model; give e.g. --models ff,narx "
                         f"(known: {', '.join(sorted(MODELS))})")
    bad = [m for m in models if m not in MODELS]
    if bad:
        raise InputError(f"--models: unknown model(s) {bad}; known: {', '.join(sorted(MODELS))}")
    twice = sorted({m for m in models if models.count(m) > 1})
    if twice:
        raise InputError(f"--models {args.models}: {', '.join(twice)} named twice; name each model once")
    for m in models:
        component(m, "--models", "the bundle folder models/NAME")
    overrides = parse_overrides(args.set)
    stray = sorted(set(overrides) - set(models))
    if stray:
        item = next(i for i in args.set if i.split(".", 1)[0].strip() == stray[0])
        raise InputError(f"--set {item}: {stray[0]} is not one of the models trained (--models "
                         f"{','.join(models)}); the setting would be ignored")
    if args.tune is not None:
        check_count(args.tune, 1, MAX_TUNE_TRIALS, "--tune", "trials per model; each trains a network")
    from nnmodel.training import execution
    settings = parallel_settings(args)
    if args.devices > 1 and not settings.serial:
        raise InputError("--devices trains one network on several processes, --workers/--scheduler trains several "
                         "networks side by side; use one of them")
    strategy = args.strategy or ("ddp_spawn" if args.devices > 1 else "auto")
    with execution(args.devices, strategy):
        summary = train_compare(args.dataset, models, args.out, overrides=overrides,
                                max_time_s=args.max_time_s, overwrite=args.overwrite, progress=not args.quiet,
                                physics=args.physics, settings=settings, tune=args.tune,
                                rh_tolerance=args.rh_tolerance, accelerator=args.accelerator)
    print(format_table(summary))
    best = summary["best_heldout"]
    if best:
        print(f"best free-run NRMSE on {best['group']}: {best['model']} {100 * best['nrmse']:.2f} %")
    from nnmodel.shortfalls import sentences
    for f in (f for r in summary["models"].values() for f in r.get("shortfalls", [])):
        first, *causes = sentences(f)
        print(first + "".join(f"\n  - {c}" for c in causes))
    print(f"report: {args.out}/index.html")
    return 0
