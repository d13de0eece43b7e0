"""Test set-up: the measured Silverbox benchmark is read where it lies beside the checkout
(``../shared/benchmarks/silverbox``) unless ``EAP_SILVERBOX`` says otherwise; the package
itself never looks there (it takes ``--data`` or ``EAP_SILVERBOX``).

The suite runs one process per core (``-n auto``, pytest-xdist); each process then gets an
equal share of the cores for its BLAS and torch threads, so that the processes do not spin
against each other.  The variables are set before numpy or torch is first imported."""
import os
from pathlib import Path

_WORKERS = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1") or 1)
if _WORKERS > 1:
    _share = str(max(1, len(os.sched_getaffinity(0)) // _WORKERS)
                 if hasattr(os, "sched_getaffinity") else 1)
    for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
        os.environ.setdefault(_var, _share)

_SHARED = Path(__file__).resolve().parents[2] / "shared" / "benchmarks" / "silverbox"
if "EAP_SILVERBOX" not in os.environ and _SHARED.is_dir():
    os.environ["EAP_SILVERBOX"] = str(_SHARED)
