"""``eap generate``: synthetic training dataset from the physics simulator."""
from __future__ import annotations


from nnmodel.dataset import generate, load_dataset

from ._common import add_output_options, add_parallel_options, parallel_settings

NAME = "generate"
#: argument destinations that name files or folders this command reads (never replaced by its outputs)
INPUTS = ("device", "config")
HELP = "generate a dataset (RH 40–100 %, sweeps, multisines, noise, pulses, realistic sensor)"


def add_arguments(p):
    p.add_argument("--config", default="default", help="dataset preset in configs/datasets (default, quick) or YAML")
    p.add_argument("--device", default=None, help="override the preset's device")
    p.add_argument("--effects", default=None, help="override the preset's effects")
    p.add_argument("--seed", type=int, default=None, help="override the preset's seed")
    add_output_options(p, None, "dataset folder to create")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_parallel_options(p)


def run(args) -> int:
    out = generate(args.out, args.config, overwrite=args.overwrite, progress=not args.quiet,
                   settings=parallel_settings(args), device=args.device, effects=args.effects,
                   seed=args.seed)
    ds = load_dataset(out)
    counts = {s: len(ds.entries(s)) for s in ("train", "validation", "test")}
    n = sum(e["samples"] for e in ds.meta["files"])
    print(f"dataset {out}: {counts['train']} train / {counts['validation']} validation / {counts['test']} test "
          f"records ({ds.entries('test', heldout=True).__len__()} at held-out RH "
          f"{ds.meta['rh_levels']['held_out']} %, {len(ds.entries(measurement_like=True))} measurement-like), "
          f"{n} samples at {ds.fs:g} Hz, noise floor {1e6 * ds.meta['noise_floor_m']:.2f} µm; "
          f"generated in {ds.meta['generation_time_s']:.1f} s")
    return 0
