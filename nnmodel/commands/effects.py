"""``eap effects``: list the physical effects, what they do and the parameters they use."""
from __future__ import annotations

from physics.device import all_param_specs, load_device
from physics.effects import BUILT_IN, EFFECTS, stage_of

NAME = "effects"
HELP = "list the physical effects with one-line explanations and their parameters"


def add_arguments(p):
    p.add_argument("--device", default=None, help="also show this device's values of the parameters")
    p.add_argument("--explain", default=None, metavar="ID", help="print the full explanation of one effect")


def run(args) -> int:
    dev = load_device(args.device) if args.device else None
    specs = all_param_specs()
    if args.explain:
        if args.explain not in EFFECTS:
            from physics.errors import InputError
            raise InputError(f"unknown effect {args.explain!r}; known: {', '.join(EFFECTS)}")
        print(EFFECTS[args.explain].explanation.strip())
        return 0
    for eid, on in EFFECTS.items():
        default = stage_of(on)
        if default is None:
            continue
        user = "" if eid in BUILT_IN else f"  (user effect, {on.__module__})"
        print(f"{on.id:22s} {on.summary}{user}")
        print(f"{'':22s} off: {default.summary if default is not on else '(always on)'}")
        names = [p.name for p in on.params] + [t.name for t in on.tables] + list(on.requires)
        for n in names:
            if n in specs:
                s = specs[n]
                val = f" = {dev.params[n]:.4g}" if dev is not None and n in dev.params else ""
                print(f"{'':24s}{n}{val} [{s.unit}]: {s.description}")
            else:
                have = " (present)" if dev is not None and n in dev.tables else ""
                print(f"{'':24s}{n}{have}: table")
        if on.id == "humidity" and dev is not None:
            for m in dev.humidity_maps.values():
                print(f"{'':24s}map {m.param} ({m.mode}) over RH {m.rh[0]:g}-{m.rh[-1]:g} %: {m.source}")
    for eid, cls in EFFECTS.items():
        if stage_of(cls) is not None:
            continue
        print(f"{eid:22s} {cls.summary}  (user effect, {cls.__module__})")
        for sp in cls.params:
            val = f" = {dev.params[sp.name]:.4g}" if dev is not None and sp.name in dev.params else \
                f" (default {sp.default:g})"
            print(f"{'':24s}{sp.name}{val} [{sp.unit}]: {sp.description}")
    print("\n`eap effects --explain ID` prints the physics and references of one effect; add your own with "
          "--effects-path FILE.py (see examples/effects/creep.py).")
    return 0
