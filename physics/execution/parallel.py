"""One execution layer for embarrassingly parallel work, on Dask (``dask.distributed``).

:func:`map_tasks` runs ``fn(task)`` for every task and returns the results in task order:

* ``workers=1`` (the default) runs in this process, without importing Dask;
* ``workers=N`` runs tasks in this process and, beside it, on a local cluster of N − 1
  worker *processes* started in the background (one thread each; BLAS, OpenMP and torch
  threads per worker are set so that workers × threads ≤ cores), all drawing from one queue;
  the cluster is started once per process and kept until exit, and :func:`warm_up` starts
  it early (beside serial work) so that it is ready when the tasks come;
* ``scheduler="tcp://HOST:8786"`` (or the environment variable ``EAP_SCHEDULER``) uses an
  existing Dask cluster — started by hand (``dask scheduler`` / ``dask worker``), or on
  SLURM/PBS with ``dask-jobqueue`` or on Kubernetes with ``dask-kubernetes`` (bring your
  own; the package does not depend on them).  Workers need the package installed and the
  task inputs on a shared path.

Tasks are plain data (dicts of numbers, strings and paths) and ``fn`` a module-level
function, so nothing unpicklable (open files, closures) crosses to a worker.  Every task
carries its own seed, so results are identical to the serial run whatever the worker
count.  A task that fails on the user's input raises that error alone (the user's message,
never a dump of the task); any other failure raises :class:`~physics.errors.ModelError`
naming the task.  Warnings raised in a worker process come back with its results and are
given again in this process, so they read like every other warning of the command (one
``eap CMD: warning: …`` line each) instead of a worker's raw ``UserWarning`` print-out.

Resources are bounded before anything starts: local workers at most the machine's cores
(more only queue behind each other), a scheduler address must be ``[tcp|tls]://HOST:PORT``
and must answer within :data:`CONNECT_TIMEOUT_S` seconds.
"""
from __future__ import annotations

import atexit
import os
import re
import signal
import socket
import queue
import threading
import warnings
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Callable, Sequence

from ..errors import InputError, ModelError, arg
from .progress import Progress

#: Environment variable naming an existing Dask scheduler.
SCHEDULER_ENV = "EAP_SCHEDULER"
#: Batches per worker: consecutive tasks are batched (by cost) so that small tasks (a few ms)
#: do not pay a scheduler round trip each, while the load still balances.
BATCHES_PER_WORKER = 16
_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS")
#: Seconds a scheduler has to accept a connection and answer as a Dask scheduler.
CONNECT_TIMEOUT_S = 15.0
_ADDRESS = re.compile(r"^(?:(?P<scheme>[a-z]+)://)?(?P<host>\[[0-9a-fA-F:]+\]|[A-Za-z0-9._-]+):(?P<port>\d{1,5})/?$")


def cores() -> int:
    """CPU cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def check_address(address: str) -> str:
    """``address`` of a Dask scheduler after checking its form (``tcp://HOST:PORT``,
    ``tls://HOST:PORT`` or ``HOST:PORT``)."""
    m = _ADDRESS.match(str(address).strip())
    if not m or m["scheme"] not in (None, "tcp", "tls") or not 1 <= int(m["port"]) <= 65535:
        raise InputError(f"{arg('scheduler')} {address!r}: not a Dask scheduler address; expected tcp://HOST:PORT "
                         f"(e.g. tcp://10.0.0.5:8786; the variable {SCHEDULER_ENV} takes the same form)")
    return str(address).strip()


@dataclass(frozen=True)
class ParallelSettings:
    """Where tasks run: ``workers`` local processes, or the Dask ``scheduler`` at an address."""

    workers: int = 1
    scheduler: str | None = None

    def __post_init__(self):
        if isinstance(self.workers, bool) or not isinstance(self.workers, int) or self.workers < 1:
            raise InputError(f"{arg('workers')} {self.workers!r}: must be a positive whole number")
        if self.scheduler:
            check_address(self.scheduler)
        elif self.workers > cores():
            raise InputError(f"{arg('workers')} {self.workers}: this machine gives {cores()} core(s); more local workers "
                             f"than cores only queue behind each other — use at most that many, or {arg('scheduler')} for "
                             "a cluster")

    @classmethod
    def resolve(cls, workers: int | None = None, scheduler: str | None = None) -> "ParallelSettings":
        """Settings from options, falling back to ``EAP_SCHEDULER`` for the scheduler."""
        return cls(int(workers) if workers is not None else 1, scheduler or os.environ.get(SCHEDULER_ENV) or None)

    @property
    def serial(self) -> bool:
        return self.workers == 1 and not self.scheduler


def _run_one(fn, task):
    """Run one task in a worker; failures come back as data: the error itself when it is
    the user's (:class:`InputError`, :class:`ModelError`), else its type and message."""
    try:
        return True, fn(task)
    except (InputError, ModelError) as exc:   # the user's message, raised as it is
        return False, exc
    except Exception as exc:  # reported with the task's name by map_tasks
        return False, f"{type(exc).__name__}: {exc}"


def _failure(desc: str, task, value) -> Exception:
    """The error to raise for a failed task: the user's error alone, else a ModelError
    naming the task briefly (its ``name``, or its plain settings — never a dump of its data)."""
    if isinstance(value, (InputError, ModelError)):
        return value
    if isinstance(task, dict) and isinstance(task.get("name"), str):
        label = repr(task["name"])
    else:
        plain = {k: v for k, v in task.items() if isinstance(v, (int, float, str, bool))} \
            if isinstance(task, dict) else task
        label = repr(plain)
        label = label if len(label) <= 80 else label[:80] + "…"
    return ModelError(f"{desc}: task {label} failed: {value}")


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


def _run_batch_remote(fn, batch):
    """:func:`_run_batch` in a worker process, with the warnings it raised returned as
    (category, message) rather than printed there (categories of other packages — e.g. a
    user's effect file — come back as UserWarning, which always unpickles)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ok, value = _run_batch(fn, batch)
    ours = ("builtins", "physics", "nnmodel")
    return ok, value, [(w.category if w.category.__module__.split(".")[0] in ours else UserWarning,
                        str(w.message)) for w in caught]


def map_tasks(fn: Callable, tasks: Sequence, settings: ParallelSettings | None = None, *,
              desc: str = "tasks", progress: bool = True, cost: Callable | None = None) -> list:
    """``[fn(t) for t in tasks]``, in order, run as ``settings`` says (module doc).

    ``cost(task)``: a relative cost estimate; the dearest tasks are started first (the
    results still come back in task order), so one long task does not finish alone."""
    settings = settings or ParallelSettings()
    tasks = list(tasks)
    if settings.serial or len(tasks) <= 1 and not settings.scheduler:
        out = []
        with Progress(len(tasks), desc, enabled=progress) as bar:
            for t in tasks:
                ok, value = _run_one(fn, t)
                if not ok:
                    raise _failure(desc, t, value)
                out.append(value)
                bar.update()
        return out
    costs = [1.0] * len(tasks) if cost is None else [float(cost(t)) for t in tasks]
    order = sorted(range(len(tasks)), key=lambda i: -costs[i])
    return _map_dask(fn, tasks, order, costs, settings, desc, progress)


class _Work:
    """Batches of task indices shared by this process and the Dask workers (thread-safe)."""

    def __init__(self, tasks, order, costs, n_workers: int):
        self.tasks = tasks
        self.batches = _batches(order, costs, BATCHES_PER_WORKER * n_workers)
        self.results: list = [None] * len(tasks)
        self.lock = threading.Lock()
        self.failure: Exception | None = None
        self.done = 0
        self.warnings: queue.SimpleQueue = queue.SimpleQueue()   # (category, message) from the workers

    def warn(self) -> None:
        """Give the workers' warnings received so far, in this process and thread."""
        while True:
            try:
                category, message = self.warnings.get_nowait()
            except queue.Empty:
                return
            warnings.warn(message, category, stacklevel=2)

    def take(self):
        with self.lock:
            return None if self.failure or not self.batches else self.batches.pop(0)

    def pending(self) -> bool:
        with self.lock:
            return bool(self.batches) and not self.failure

    def give_back(self, batch):
        with self.lock:
            self.batches.insert(0, batch)

    def store(self, batch, ok, value, desc) -> int:
        with self.lock:
            if not ok:
                k, err = value
                self.failure = self.failure or _failure(desc, self.tasks[batch[k]], err)
                return 0
            for i, v in zip(batch, value):
                self.results[i] = v
            self.done += len(batch)
            return len(batch)


def _batches(order, costs, n: int) -> list[list[int]]:
    """Consecutive tasks of ``order`` grouped into about ``n`` batches of similar total cost
    (a dear task alone, cheap ones together)."""
    target = sum(costs) / max(1, n)
    out, cur, acc = [], [], 0.0
    for i in order:
        cur.append(i)
        acc += costs[i]
        if acc >= target:
            out.append(cur)
            cur, acc = [], 0.0
    return out + ([cur] if cur else [])


def _map_dask(fn, tasks, order, costs, settings: ParallelSettings, desc: str, progress: bool) -> list:
    """Local runs: this process works through the tasks at once while a cluster of
    ``workers - 1`` processes starts beside it and then shares the queue (the cluster's
    start-up and the workers' first imports overlap useful work).  ``--scheduler``: every
    task goes to the existing cluster."""
    local = not settings.scheduler
    work = _Work(tasks, order, costs, settings.workers if local else 1)
    remote = _Remote(fn, work, settings, desc, None if local else _connect(settings.scheduler))
    label = f"{desc} on {settings.workers} workers" if local else f"{desc} on the cluster"
    with Progress(len(tasks), label, enabled=progress) as bar:
        seen = 0
        remote.start()
        try:
            while True:
                batch = work.take() if local else None
                if batch is not None:
                    work.store(batch, *_run_batch(fn, [tasks[i] for i in batch]), desc)
                elif remote.is_alive():
                    remote.join(0.2)
                elif not (local and work.batches and not work.failure):   # else: batches handed back
                    break
                work.warn()
                bar.update(work.done - seen)
                seen = work.done
        except BaseException:     # Ctrl-C, SIGTERM: stop the workers before the caller cleans up after
            remote.stop.set()     # them (a worker mid-task would write into a removed temporary folder)
            remote.join()
            if local:
                shutdown()
            raise
        finally:
            remote.stop.set()
            remote.join()
    work.warn()
    if work.failure:
        raise work.failure
    if work.done < len(tasks):
        raise remote.error or ModelError(f"{desc}: {len(tasks) - work.done} task(s) were not run")
    return work.results


class _Remote(threading.Thread):
    """The Dask side of :func:`_map_dask`: start (or join) the cluster, keep two batches in
    flight per worker until the queue is empty, store the results; on an error, hand the
    unfinished batches back (this process then runs them) and keep the error."""

    def __init__(self, fn, work: _Work, settings: ParallelSettings, desc: str, client=None):
        super().__init__(daemon=True)
        self.fn, self.work, self.settings, self.desc, self.client = fn, work, settings, desc, client
        self.stop = threading.Event()
        self.error: BaseException | None = None

    def run(self) -> None:
        client = self.client
        flying: dict = {}
        try:
            if client is None:
                starting = _local_cluster(self.settings.workers)
                while not starting.done():   # this process works meanwhile; stop when nothing is left
                    if self.stop.wait(0.1) or not self.work.pending():
                        return
                client = starting.result()
            n_workers = max(1, len(client.scheduler_info()["workers"]))
            from distributed import wait
            while not self.stop.is_set():
                while len(flying) < 2 * n_workers:
                    batch = self.work.take()
                    if batch is None:
                        break
                    fut = client.submit(_run_batch_remote, self.fn, [self.work.tasks[i] for i in batch], pure=False)
                    flying[fut] = batch
                if not flying:
                    break
                try:
                    done = wait(list(flying), timeout=0.2, return_when="FIRST_COMPLETED").done
                except TimeoutError:   # nothing finished within the poll interval
                    continue
                for fut in done:
                    ok, value, caught = fut.result()
                    for w in caught:
                        self.work.warnings.put(w)
                    self.work.store(flying.pop(fut), ok, value, self.desc)
        except BaseException as exc:  # raised by the main thread if work is left undone
            self.error = exc
        finally:
            for fut, batch in flying.items():
                fut.cancel()
                self.work.give_back(batch)
            if client is not None and self.settings.scheduler:
                client.close()   # a local cluster is kept for this process's next map_tasks


def _connect(address: str):
    """A client of the existing Dask scheduler at ``address``: the port must accept a
    connection, and a Dask scheduler answer there, within :data:`CONNECT_TIMEOUT_S`."""
    m = _ADDRESS.match(check_address(address))
    host, port = m["host"].strip("[]"), int(m["port"])
    hint = f"start a scheduler there (dask scheduler) or unset {SCHEDULER_ENV}"
    try:
        socket.create_connection((host, port), timeout=CONNECT_TIMEOUT_S).close()
    except OSError as exc:
        why = "timed out" if isinstance(exc, TimeoutError) else exc.strerror or str(exc)
        raise InputError(f"{arg('scheduler')} {address}: cannot connect ({why}); {hint}") from None
    result: dict = {}

    def connect():
        try:
            from distributed import Client
            result["client"] = Client(address if m["scheme"] else f"tcp://{address}", timeout=CONNECT_TIMEOUT_S)
        except BaseException as exc:   # reported below
            result["error"] = exc
    t = threading.Thread(target=connect, daemon=True)
    t.start()
    t.join(CONNECT_TIMEOUT_S + 5.0)
    if "client" not in result:
        err = result.get("error")
        if t.is_alive():
            why = f"no Dask scheduler answered within {CONNECT_TIMEOUT_S:g} s"
        elif isinstance(err, (OSError, TimeoutError)):
            why = f"cannot connect ({' '.join(str(err).split())[:160]})"
        else:   # a reply that is not Dask's protocol (e.g. a length of exabytes): not a scheduler
            why = "something answers there, but not as a Dask scheduler"
        raise InputError(f"{arg('scheduler')} {address}: {why}; {hint}")
    return result["client"]


_CLUSTERS: dict[int, Future] = {}
_CLUSTERS_LOCK = threading.Lock()


def warm_up(settings: ParallelSettings | None) -> None:
    """Start the local cluster of ``settings`` now, in the background, so that it is ready
    when the first :func:`map_tasks` needs it (call it before serial work that precedes the
    parallel part, e.g. the diagnosis's base fit).  No-op when serial or on ``--scheduler``."""
    if settings is not None and not settings.serial and not settings.scheduler:
        _local_cluster(settings.workers)


def _local_cluster(workers: int) -> Future:
    """The client of this process's local cluster of ``workers − 1`` worker processes,
    started once in a background thread and kept (closed at exit) for later calls."""
    with _CLUSTERS_LOCK:
        fut = _CLUSTERS.get(workers)
        if fut is None:
            if not _CLUSTERS:
                atexit.register(shutdown)
            fut = _CLUSTERS[workers] = Future()
            threading.Thread(target=_start_cluster, args=(workers, fut), daemon=True).start()
        return fut


def _start_cluster(workers: int, fut: Future) -> None:
    try:
        import dask
        from distributed import Client, LocalCluster
        _workers_leave_ctrl_c_to_this_process()
        # another cluster on this machine holds the dashboard port: not the user's concern
        warnings.filterwarnings("ignore", message="Port .* is already in use", category=UserWarning)
        cores = os.cpu_count() or 1
        env = {v: str(max(1, cores // workers)) for v in _THREAD_VARS}
        # task errors come back through the futures; the cluster's own log (a worker's heartbeat
        # traceback when Ctrl-C or SIGTERM closes the scheduler under it) is not the user's concern
        with dask.config.set({"distributed.nanny.pre-spawn-environ": env, "distributed.worker.daemon": False,
                              "distributed.logging.distributed": "critical"}):
            cluster = LocalCluster(n_workers=workers - 1, threads_per_worker=1, processes=True,
                                   dashboard_address=None, silence_logs=50, env=env)
        client = Client(cluster)
        client.eap_cluster = cluster
        fut.set_result(client)
    except BaseException as exc:   # every later map_tasks then runs in this process
        fut.set_exception(exc)


def _workers_leave_ctrl_c_to_this_process() -> None:
    """Block SIGINT in the calling (cluster-starting) thread: the threads it starts and the worker
    processes they spawn inherit the mask, so a Ctrl-C to the terminal's process group reaches
    this process alone, which stops the run and closes the cluster; a worker still importing
    once printed its own KeyboardInterrupt traceback.  Other threads of this process (the main
    one) do not block it, so the user's Ctrl-C is never lost.  The multiprocessing resource
    tracker is started first: starting it *unblocks* SIGINT in its caller (CPython's
    ``resource_tracker.ensure_running``), which had silently undone the mask.  Nothing to do
    where threads have no signal mask (Windows: no process groups either)."""
    if not hasattr(signal, "pthread_sigmask"):
        return
    from multiprocessing import resource_tracker
    resource_tracker.ensure_running()
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})


def shutdown() -> None:
    """Close the local clusters this process started (also done at exit)."""
    with _CLUSTERS_LOCK:
        started = list(_CLUSTERS.values())
        _CLUSTERS.clear()
    for fut in started:
        if fut.done() and fut.exception() is None:
            client = fut.result()
            client.close()
            client.eap_cluster.close()
