"""Tutorial 7: scale out on Dask — the same sweep on one process, on local workers and
on a Dask cluster, with identical results.

Run from anywhere:  python docs/tutorials/t7_dask.py
"""
import time

from _tutorial import check, eap, out

OUT = out("t7")
# 8 stiffness values x 7 humidities = 56 frequency responses of the thesis strip
GRID = ["--device", "ipmc_pt_eg", "--effects", "humidity", "--grid", "Y=log:1e8:1e9:8",
        "--grid", "rh=lin:40:100:7", "--quiet"]


def table(name: str) -> str:
    return (OUT / f"sweep_{name}.csv").read_text(encoding="utf-8")


def main() -> None:
    timing = {}
    for name, workers in (("one", "1"), ("two", "2")):
        start = time.perf_counter()
        eap("sweep", *GRID, "--workers", workers, "--out", OUT / f"sweep_{name}.csv",
            "--overwrite")
        timing[name] = time.perf_counter() - start
    print(f"wall time: {timing['one']:.1f} s on one process, {timing['two']:.1f} s with "
          "two workers (their start-up is paid once per command)")
    check(table("one") == table("two"), "the tables are identical for any worker count")
    check(table("one").count("\n") == 1 + 8 * 7, "one row per grid point")

    # --- An existing cluster: here a local one, started the way you would start any ---
    # (on machines: `dask scheduler` on one, `dask worker tcp://HOST:8786` on the others)
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster:
        eap("sweep", *GRID, "--scheduler", cluster.scheduler_address,
            "--out", OUT / "sweep_cluster.csv", "--overwrite")
    check(table("cluster") == table("one"),
          "and identical on the cluster, given by its scheduler's address")


if __name__ == "__main__":      # worker processes import this file again
    main()
