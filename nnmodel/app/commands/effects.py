"""``eap effects``: list the physical effects, what they do and the parameters they use; with
``--device`` also the device's own parameters (what ``--param`` takes); ``--check FILE.py``
runs the effect contract on the effects of a file."""
from __future__ import annotations

from physics.device import all_param_specs, load_device
from physics.effects import BUILT_IN, EFFECTS, check_effect, effect_classes_in_file, stage_of
from physics.parameters import BASE_SECTIONS

NAME = "effects"
#: argument destinations that name files or folders this command reads (never replaced by its outputs)
INPUTS = ("device", "check")
#: takes --effects-path although it has no --effects option
TAKES_EFFECT_FILES = True
HELP = "list the physical effects with one-line explanations and their parameters"
DESCRIPTION = (HELP + ". With --device, also the device's geometry and material parameters that --param takes. "
               "--check FILE.py runs the effect contract (physics.effects.check_effect) on the effects of a file.")


def add_arguments(p):
    p.add_argument("--device", default=None,
                   help="also list this device's parameters (those --param NAME=VALUE takes) and its values")
    p.add_argument("--explain", default=None, metavar="ID", help="print the full explanation of one effect")
    p.add_argument("--check", default=None, metavar="FILE.py",
                   help="run the effect contract on every effect defined in FILE.py (one line per check); "
                        "exit 1 if one fails. The file is CODE: it is imported and run with your rights (see "
                        "docs/security.md)")
    p.add_argument("--fast", action="store_true",
                   help="with --check: the quick checks only (declaration, model, hooks, finite, stable, passive)")


def run(args) -> int:
    if args.check:
        return _check(args.check, args.device, args.fast)
    dev = load_device(args.device) if args.device else None
    specs = all_param_specs()
    if args.explain:
        if args.explain not in EFFECTS:
            from physics.errors import InputError
            raise InputError(f"unknown effect {args.explain!r}; known: {', '.join(EFFECTS)}")
        print(EFFECTS[args.explain].explanation.strip())
        return 0
    if dev is not None:
        _device_parameters(dev)
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
        if on.needs_rh and dev is not None:
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
          "--effects-path FILE.py (see examples/effects/creep.py) and check it with --check FILE.py.")
    return 0


def _device_parameters(dev) -> None:
    """The device's base parameters, by section: what ``--param NAME=VALUE`` takes."""
    print(f"device {dev.name}: {dev.title}")
    print("parameters (--param NAME=VALUE with a unit, e.g. --param L_total=40mm; values in SI; the effects' own "
          "parameters are listed with each effect below)")
    for section, specs in BASE_SECTIONS.items():
        print(f"  {section}")
        for name, s in specs.items():
            val = f"{dev.params[name]:<11.5g}" if name in dev.params else f"{'(not given)':11s}"
            print(f"    {name:14s} = {val} {s.unit:9s} {s.description}")
    L, Lc = dev.params.get("L_total"), dev.params.get("L_clamp")
    if L is not None and Lc is not None:
        print(f"  L_total includes the clamp: the free (bending) length is L_total − L_clamp = {L - Lc:.5g} m")
    print()


def _check(path, device, fast: bool) -> int:
    """Run :func:`physics.effects.check_effect` on every effect of ``path``; 1 if one fails."""
    from physics.errors import InputError
    try:
        classes = effect_classes_in_file(path)
    except InputError as exc:            # the file was named with --check, not --effects-path
        raise InputError(exc.render(lambda name: "--check" if name == "effects_path" else None)) from None
    failed = 0
    for cls in classes:
        report = check_effect(cls, device or "ipmc_pt_eg", fast=fast)
        print(report)
        failed += not report.ok
    return 1 if failed else 0
