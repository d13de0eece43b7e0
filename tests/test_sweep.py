"""Parameter sweeps and the execution layer: closed-form beam scaling, identical results for
any worker count, clear errors."""
import os

import pandas as pd
import pytest

from nnmodel.app.cli import main
from physics.errors import InputError, ModelError
from physics.execution.parallel import ParallelSettings, map_tasks
from physics.solvers.sweep import parse_grid, run_sweep


def test_first_resonance_follows_euler_bernoulli_scaling():
    """f1 = (1.8751²/2π) √(EI/ρA) / L²: ∝ √Y at fixed geometry and ∝ 1/L² in the free length."""
    t = run_sweep("ipmc_pt_eg", "none", {"Y": [1e8, 4e8]}, rh=60.0, progress=False)
    assert t.resonance_Hz[1] / t.resonance_Hz[0] == pytest.approx(2.0, rel=2e-3)
    from physics.device import load_device
    d = load_device("ipmc_pt_eg")
    Lc = d["L_clamp"]
    L1, L2 = 0.02, 0.03
    t = run_sweep("ipmc_pt_eg", "none", {"L_total": [Lc + L1, Lc + L2]}, rh=60.0, f_range=(0.1, 400.0),
                  progress=False)
    assert t.resonance_Hz[0] / t.resonance_Hz[1] == pytest.approx((L2 / L1) ** 2, rel=5e-3)


def test_two_workers_give_the_same_table():
    grid = {"Y": [1e8, 2e8, 3e8], "rh": [40.0, 80.0]}
    serial = run_sweep("ipmc_pt_eg", "none", grid, progress=False)
    parallel = run_sweep("ipmc_pt_eg", "none", grid, settings=ParallelSettings(2), progress=False)
    pd.testing.assert_frame_equal(serial, parallel)
    assert list(serial.columns[:2]) == ["Y", "rh"] and len(serial) == 6


def _fails_on_three(task):
    if task["x"] == 3:
        raise ValueError("bad x")
    return task["x"]


def _slow_square(task):
    import time
    time.sleep(task.get("sleep", 0.0))
    return task["x"] ** 2


def _square_and_pid(task):
    import os
    return _slow_square(task), os.getpid()


@pytest.mark.parametrize("workers", [1, 2])
def test_failed_task_names_its_inputs(workers):
    with pytest.raises(ModelError, match=r"task \{'x': 3\} failed: ValueError: bad x"):
        map_tasks(_fails_on_three, [{"x": i} for i in range(5)], ParallelSettings(workers), progress=False)
    with pytest.raises(InputError, match="workers 0: must be a positive"):
        ParallelSettings(0)


def test_grid_errors_and_command(tmp_path, capsys):
    from physics.device import load_device
    dev = load_device("ipmc_pt_eg")
    for item, msg in [("Yy=1,2", "unknown parameter"), ("Y=abc", "expected numbers"),
                      ("rh=120", "0–100"), ("Y=log:0:1:3", "positive ends"), ("Y", "NAME=VALUES")]:
        with pytest.raises(InputError, match=msg):
            parse_grid([item], dev)
    out = tmp_path / "s.csv"
    assert main(["sweep", "--effects", "none", "--grid", "Y=lin:1e8:2e8:3", "--rh", "60", "--out", str(out),
                 "--quiet"]) == 0
    assert len(pd.read_csv(out)) == 3 and "3 points" in capsys.readouterr().out
    assert main(["sweep", "--grid", "Y=1e8", "--out", str(out)]) == 2
    assert "--overwrite" in capsys.readouterr().err


def test_generate_on_two_workers_writes_identical_files(tmp_path):
    import json
    from nnmodel.dataset import generate
    cfg = dict(duration_s=4.0, train_rh_pct=[40, 80], heldout_rh_pct=[60], excitations=["sweep", "noise"],
               varying_rh={"train": 0, "test": 0, "range_pct": [40, 100]},
               measurement_like={"effects": [], "count": 0, "rh_pct": [70]})
    a = generate(tmp_path / "a", "quick", progress=False, **cfg)
    b = generate(tmp_path / "b", "quick", progress=False, settings=ParallelSettings(2), **cfg)
    ha = [e["sha256"] for e in json.loads((a / "dataset.json").read_text())["files"]]
    hb = [e["sha256"] for e in json.loads((b / "dataset.json").read_text())["files"]]
    assert ha == hb and len(ha) >= 6


def test_this_process_and_the_workers_share_the_queue_in_task_order():
    """With 2 workers this process starts at once and a worker joins when its cluster is up;
    the dearest tasks (by `cost`) start first; results come back in task order."""
    import os
    tasks = [{"x": i, "sleep": 0.1} for i in range(60)]
    out = map_tasks(_square_and_pid, tasks, ParallelSettings(2), progress=False, cost=lambda t: t["x"] % 7)
    assert [v for v, _ in out] == [i ** 2 for i in range(60)]
    pids = [p for _, p in out]
    mine = pids.count(os.getpid())
    assert 0 < mine < len(pids), f"this process ran {mine} of {len(pids)} tasks: the worker never joined"
    assert len(set(pids)) == 2


def _warn_and_pid(task):
    import os
    import time
    import warnings
    time.sleep(0.1)
    warnings.warn(f"task {task['x']} looks odd", UserWarning)
    return os.getpid()


def test_warnings_of_worker_processes_read_like_the_command_s_own(capsys):
    """A warning raised in a Dask worker process comes back with its result and is given in
    this process, so the command line shows it as one ``eap CMD: warning: …`` line (as a
    warning of this process), not as the worker's raw UserWarning print-out."""
    import os
    import warnings
    from nnmodel.app.cli import _notice
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.showwarning = _notice("sweep")
        pids = map_tasks(_warn_and_pid, [{"x": i} for i in range(40)], ParallelSettings(2), progress=False)
    assert any(p != os.getpid() for p in pids), "no task ran on the worker"
    err = capsys.readouterr().err.splitlines()
    for i in range(40):
        assert f"eap sweep: warning: task {i} looks odd" in err


@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="reads the signal mask from /proc")
def test_local_workers_leave_ctrl_c_to_the_command():
    """A Ctrl-C reaches the terminal's whole process group: a worker still importing printed its
    own KeyboardInterrupt traceback after 'eap sweep: interrupted'.  The workers start with SIGINT
    blocked (the resource tracker once unblocked it in the starting thread), this process's main
    thread does not block it."""
    import signal

    from physics.execution.parallel import _local_cluster
    client = _local_cluster(2).result(timeout=120)
    for pid in client.run(os.getpid).values():
        blocked = next(int(line.split()[1], 16) for line in open(f"/proc/{pid}/status") if line.startswith("SigBlk"))
        assert blocked >> (signal.SIGINT - 1) & 1, f"worker {pid} has SIGINT unblocked"
    assert signal.SIGINT not in signal.pthread_sigmask(signal.SIG_BLOCK, [])
