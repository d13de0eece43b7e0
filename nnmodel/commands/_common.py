"""Options shared by several commands."""
from __future__ import annotations

import argparse
import json
import platform
import sys
from pathlib import Path

from physics.errors import InputError


def add_model_options(p: argparse.ArgumentParser, rh_required: bool = False) -> None:
    p.add_argument("--device", default="ipmc_pt_eg",
                   help="device name in configs/devices (ipmc_pt_eg, ip2c_pedot_water) or a YAML path")
    p.add_argument("--effects", default="default",
                   help="comma-separated effect ids, or default / linear / all / none (see `eap effects`)")
    p.add_argument("--rh", type=float, default=None, required=rh_required,
                   help="relative humidity [%%] (needed when the humidity effect is on)")
    p.add_argument("--n-modes", type=int, default=4, help="retained bending modes (the rest is quasi-static)")


def out_dir(path: str, overwrite: bool = False) -> Path:
    d = Path(path)
    if d.exists() and not d.is_dir():
        raise InputError(f"--out {d} exists and is not a folder")
    d.mkdir(parents=True, exist_ok=True)
    return d


def provenance(argv=None) -> dict:
    from importlib.metadata import PackageNotFoundError, version
    try:
        ver = version("eap-model")
    except PackageNotFoundError:
        ver = "unknown"
    return {"package": "eap-model", "version": ver, "python": platform.python_version(),
            "command": " ".join(["eap"] + (sys.argv[1:] if argv is None else list(argv)))}


def dumps(obj) -> str:
    return json.dumps(obj, indent=2)
