"""One execution layer for embarrassingly parallel work, on Dask (``dask.distributed``).

:func:`map_tasks` runs ``fn(task)`` for every task and returns the results in task order:

* ``workers=1`` (the default) runs in this process, without importing Dask;
* ``workers=N`` starts a local cluster of N worker *processes* (one thread each; BLAS,
  OpenMP and torch threads per worker are set so that workers × threads ≤ cores);
* ``scheduler="tcp://HOST:8786"`` (or the environment variable ``EAP_SCHEDULER``) uses an
  existing Dask cluster — started by hand (``dask scheduler`` / ``dask worker``), or on
  SLURM/PBS with ``dask-jobqueue`` or on Kubernetes with ``dask-kubernetes`` (bring your
  own; the package does not depend on them).  Workers need the package installed and the
  task inputs on a shared path.

Tasks are plain data (dicts of numbers, strings and paths) and ``fn`` a module-level
function, so nothing unpicklable (open files, closures) crosses to a worker.  Every task
carries its own seed, so results are identical to the serial run whatever the worker
count.  A failing task raises :class:`~physics.errors.ModelError` naming the task.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Callable, Sequence

from .errors import InputError, ModelError
from .progress import Progress

#: Environment variable naming an existing Dask scheduler.
SCHEDULER_ENV = "EAP_SCHEDULER"
#: Dask tasks per worker: consecutive tasks are batched so that small tasks (a few ms)
#: do not pay a scheduler round trip each, while the load still balances.
BATCHES_PER_WORKER = 8
_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS")


@dataclass(frozen=True)
class ParallelSettings:
    """Where tasks run: ``workers`` local processes, or the Dask ``scheduler`` at an address."""

    workers: int = 1
    scheduler: str | None = None

    def __post_init__(self):
        if isinstance(self.workers, bool) or not isinstance(self.workers, int) or self.workers < 1:
            raise InputError(f"--workers {self.workers!r}: must be a positive whole number")

    @classmethod
    def resolve(cls, workers: int | None = None, scheduler: str | None = None) -> "ParallelSettings":
        """Settings from options, falling back to ``EAP_SCHEDULER`` for the scheduler."""
        return cls(int(workers) if workers is not None else 1, scheduler or os.environ.get(SCHEDULER_ENV) or None)

    @property
    def serial(self) -> bool:
        return self.workers == 1 and not self.scheduler


def _run_one(fn, task):
    """Run one task in a worker; failures come back as data (the traceback stays readable)."""
    try:
        return True, fn(task)
    except Exception as exc:  # reported with the task's inputs by map_tasks
        return False, f"{type(exc).__name__}: {exc}"


def _run_batch(fn, batch):
    """Run consecutive tasks in one worker call (fewer round trips for small tasks); stops
    at the first failure, which is returned with its index in the batch."""
    out = []
    for k, task in enumerate(batch):
        ok, value = _run_one(fn, task)
        if not ok:
            return False, (k, value)
        out.append(value)
    return True, out


def _describe(task, limit: int = 200) -> str:
    text = repr(task)
    return text if len(text) <= limit else text[:limit] + "…"


def map_tasks(fn: Callable, tasks: Sequence, settings: ParallelSettings | None = None, *,
              desc: str = "tasks", progress: bool = True) -> list:
    """``[fn(t) for t in tasks]``, in order, run as ``settings`` says (module doc)."""
    settings = settings or ParallelSettings()
    tasks = list(tasks)
    if settings.serial or len(tasks) <= 1 and not settings.scheduler:
        out = []
        with Progress(len(tasks), desc, enabled=progress) as bar:
            for t in tasks:
                ok, value = _run_one(fn, t)
                if not ok:
                    raise ModelError(f"{desc}: task {_describe(t)} failed: {value}")
                out.append(value)
                bar.update()
        return out
    return _map_dask(fn, tasks, settings, desc, progress)


def _map_dask(fn, tasks, settings: ParallelSettings, desc: str, progress: bool) -> list:
    import dask
    from distributed import Client, LocalCluster, as_completed

    cluster = client = None
    cores = os.cpu_count() or 1
    threads = max(1, cores // settings.workers)
    env = {v: str(threads) for v in _THREAD_VARS}
    try:
        if settings.scheduler:
            try:
                client = Client(settings.scheduler, timeout="20s")
            except (OSError, TimeoutError) as exc:
                raise InputError(f"--scheduler {settings.scheduler}: cannot connect ({exc}); start a scheduler "
                                 f"there or unset {SCHEDULER_ENV}") from None
        else:
            with dask.config.set({"distributed.nanny.pre-spawn-environ": env,
                                  "distributed.worker.daemon": False,
                                  "distributed.logging.distributed": "error"}):
                cluster = LocalCluster(n_workers=settings.workers, threads_per_worker=1, processes=True,
                                       dashboard_address=None, silence_logs=40, env=env)
                client = Client(cluster)
        n_workers = max(1, len(client.scheduler_info()["workers"]))
        size = max(1, len(tasks) // (BATCHES_PER_WORKER * n_workers))
        starts = list(range(0, len(tasks), size))
        futures = client.map(_run_batch, [fn] * len(starts), [tasks[a:a + size] for a in starts], pure=False)
        index = {f.key: a for f, a in zip(futures, starts)}
        results: list = [None] * len(tasks)
        with Progress(len(tasks), f"{desc} on {n_workers} workers", enabled=progress) as bar:
            for fut in as_completed(futures):
                a = index[fut.key]
                ok, value = fut.result()
                if not ok:
                    for f in futures:
                        f.cancel()
                    k, msg = value
                    raise ModelError(f"{desc}: task {_describe(tasks[a + k])} failed: {msg}")
                results[a:a + len(value)] = value
                bar.update(len(value))
        return results
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
