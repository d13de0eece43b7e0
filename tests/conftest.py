"""Test set-up: the measured Silverbox benchmark is read where it lies beside the checkout
(``../shared/benchmarks/silverbox``) unless ``EAP_SILVERBOX`` says otherwise; the package
itself never looks there (it takes ``--data`` or ``EAP_SILVERBOX``)."""
import os
from pathlib import Path

_SHARED = Path(__file__).resolve().parents[2] / "shared" / "benchmarks" / "silverbox"
if "EAP_SILVERBOX" not in os.environ and _SHARED.is_dir():
    os.environ["EAP_SILVERBOX"] = str(_SHARED)
