"""Time (and peak RSS) for `eap predict` to refuse a bundle whose card asks for a huge network.

For each network kind a small bundle is trained (seconds), then each structural size in its
card (layers, width, centres, lags, memory filters, ..., the samples it starts from, the
hybrid's gain network and physics modes) is set to ``--value`` in turn and
`eap predict` is run on a short record in a fresh process with an address-space cap. A held
case is exit 2 with one ``eap predict: error:`` line naming the entry and its cap ("at most
N", "within 1–N") and no traceback; the script prints the
wall time of the whole process (imports included, ≈ the time of `eap effects`) and its peak RSS.

    python bench/oversized_cards.py                    # ff, rbf, narx, lstm, hybrid; value 1e8
    python bench/oversized_cards.py --kinds ff --value 100000
"""
from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from memory_long_records import RUNNER

#: Card entries that set the size of a network (allocation grows with them); training-only
#: settings (RBF width_neighbours, kmeans_samples, batch_size, horizon) are not read by predict.
SIZES = ("na", "nb", "hidden", "layers", "n_centres", "n_init", "encoder_hidden", "gain_hidden", "memory_filters",
         "poly_degree")
#: Sizes elsewhere in a card (dotted paths from its top): the hybrid's physics part (its
#: retained bending modes).  The card's top-level ``n_init`` is informational: a bundle's
#: starting samples are derived from its lags when it is loaded.
CARD_SIZES = ("physics.n_modes",)


def _entries(card: dict) -> list[tuple[str, ...]]:
    """Paths (from the card's top) of the size entries present in ``card``."""
    paths = [("hyper_parameters", k) for k in SIZES if k in card["hyper_parameters"]]
    for dotted in CARD_SIZES:
        path, node = tuple(dotted.split(".")), card
        for k in path[:-1]:
            node = node.get(k) if isinstance(node, dict) else None
        if isinstance(node, dict) and path[-1] in node:
            paths.append(path)
    return paths


def _bundle(folder: Path, kind: str) -> Path:
    from scipy.signal import lfilter

    from nnmodel.bundle import save
    from nnmodel.data import Experiment
    from nnmodel.models import MODELS
    rng = np.random.default_rng(0)
    u = np.convolve(rng.normal(size=600), np.ones(4) / 4, "same")
    rec = Experiment(u=u, y=lfilter([0.05], [1, -0.95], u) * 1e-3, rh=np.full(u.size, 60.0), fs=50.0)
    cls = MODELS[kind]
    m = cls(**{"progress_bar": False, **cls.CHECK_PARAMS})
    m.fit([rec], [rec])
    return save(m, folder / kind)


def _run(cap_gb: float, argv: list[str]) -> dict:
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", RUNNER, str(cap_gb), *argv], capture_output=True, text=True,
                          timeout=600)
    wall = time.perf_counter() - t0
    stats = [json.loads(ln) for ln in proc.stdout.splitlines() if ln.startswith("{")]
    err = [ln for ln in proc.stderr.strip().splitlines() if ln.strip()]
    return {"wall_s": wall, "peak_MB": stats[-1]["peak_MB"] if stats else float("nan"),
            "rc": stats[-1]["rc"] if stats else proc.returncode, "err": err[-1] if err else "",
            "traceback": "Traceback" in proc.stderr}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kinds", default="ff,rbf,narx,lstm,hybrid", help="network kinds to try")
    ap.add_argument("--value", type=float, default=1e8, help="the size written into the card")
    ap.add_argument("--cap-GB", type=float, default=4.0, help="address-space cap per run")
    args = ap.parse_args()
    value = int(args.value)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        rec = tmp / "rec.csv"
        t = np.arange(500) / 50.0
        np.savetxt(rec, np.column_stack([t, np.sin(t), np.full(t.size, 60.0)]), delimiter=",",
                   header="time_s,voltage_V,rh_pct", comments="")
        base = _run(args.cap_GB, ["effects"])
        print(f"baseline (imports, `eap effects`): {base['wall_s']:.1f} s, {base['peak_MB']:.0f} MB")
        print(f"{'kind':6s} {'card entry':24s} {'wall s':>7s} {'peak MB':>8s}  outcome")
        held = tried = 0
        for kind in args.kinds.split(","):
            bundle = _bundle(tmp, kind)
            card = json.loads((bundle / "card.json").read_text())
            for path in _entries(card):
                edited = json.loads(json.dumps(card))
                node = edited
                for k in path[:-1]:
                    node = node[k]
                node[path[-1]] = value
                key = path[-1] if path[0] == "hyper_parameters" else ".".join(path)
                (bundle / "card.json").write_text(json.dumps(edited))
                r = _run(args.cap_GB, ["predict", "--model", str(bundle), "--input", str(rec), "--out",
                                       str(tmp / "p.csv"), "--overwrite"])
                names_cap = re.search(r"at most [\d,]+|within [\d,]+–[\d,]+", r["err"]) is not None
                ok = (r["rc"] == 2 and r["err"].startswith("eap predict: error:") and not r["traceback"]
                      and path[-1] in r["err"] and names_cap)
                tried += 1
                held += ok
                print(f"{kind:6s} {key + '=' + format(value, 'g'):24s} {r['wall_s']:7.1f} {r['peak_MB']:8.0f}  "
                      f"{'refused' if ok else 'NOT REFUSED (exit ' + str(r['rc']) + ')'}: {r['err'][:220]}",
                      flush=True)
            (bundle / "card.json").write_text(json.dumps(card))
        print(f"refused {held} of {tried} oversized cards")


if __name__ == "__main__":
    main()
