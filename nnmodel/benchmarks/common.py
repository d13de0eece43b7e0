"""Pieces shared by benchmark suites: model construction from recipes with suite
overrides, timing, text tables and a self-contained HTML page."""
from __future__ import annotations

import os
import platform
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from physics.errors import InputError

__all__ = ["build_model", "parse_models", "start", "time_free_run", "text_table", "page",
           "environment", "fmt"]


def parse_models(models, default: Sequence[str]) -> list[str]:
    """Model names from a list or a comma-separated string; validated against the registry."""
    from ..models import MODELS

    if models is None or models == "" or models == []:
        names = list(default)
    elif isinstance(models, str):
        names = [m.strip() for m in models.split(",") if m.strip()]
    else:
        names = [n.strip() for m in models for n in str(m).split(",") if n.strip()]
    bad = [n for n in names if n not in MODELS]
    if bad:
        raise InputError(f"unknown model(s) {bad}; known: {', '.join(MODELS)}")
    if len(set(names)) != len(names):
        raise InputError(f"model listed twice in {names}")
    return names


def start(models, default: Sequence[str], overrides: dict | None, out) -> tuple[list[str], dict, Path]:
    """Common start of a suite: the model names (:func:`parse_models`), the per-model
    overrides (refused for models not being run) and the output folder (created)."""
    names = parse_models(models, default)
    overrides = overrides or {}
    bad = sorted(set(overrides) - set(names))
    if bad:
        raise InputError(f"overrides given for model(s) {bad} that are not being run ({names})")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    return names, overrides, out


def finish(echo, table: str, findings: Sequence[str], report_line: str) -> None:
    """Common end of a suite: its table, its findings and where the report was written."""
    echo("")
    echo(table)
    echo("")
    for line in findings:
        echo(line)
    echo(report_line)


def build_model(name: str, *layers: dict | None):
    """Model ``name`` from its recipe, updated by each override dict in turn."""
    from ..recipes import load_recipe
    from ..models import MODELS

    merged: dict = {}
    for layer in layers:
        merged.update(layer or {})
    rec = load_recipe(name, merged)
    return MODELS[rec["model"]](**rec["hyper_parameters"])


def time_free_run(model, u, y_init=None, rh=None, repeats: int = 1) -> tuple[np.ndarray, float]:
    """Free-run simulation and its speed in simulated samples per second."""
    best = np.inf
    y = None
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        y = model.simulate(u, rh=rh, y_init=y_init)
        best = min(best, time.perf_counter() - t0)
    n = len(u) - (0 if y_init is None else len(y_init))
    return y, n / best if best > 0 else float("inf")


def fmt(v, nd=3) -> str:
    if v is None:
        return "-"
    if isinstance(v, str):
        return v
    if isinstance(v, (int, np.integer)):
        return f"{int(v):d}"
    v = float(v)
    if not np.isfinite(v):
        return "inf"
    if abs(v) >= 1e4:
        return f"{v:.3g}"
    return f"{v:.{nd}f}"


def text_table(header: Sequence[str], rows: Sequence[Sequence]) -> str:
    cells = [[str(h) for h in header]] + [[c if isinstance(c, str) else fmt(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    def line(r):
        return "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths)))
    sep = "  ".join("-" * w for w in widths)
    return "\n".join([line(cells[0]), sep] + [line(r) for r in cells[1:]])


def page(title: str, blocks: Sequence[tuple[str, object]]):
    """A suite's page through the one report builder (a :class:`physics.pages.report.Report`;
    write it with ``.write_index(out, old_name="SUITE.html")``).  ``blocks`` are (kind,
    content): ``("h2", text)``, ``("p", text or (text, links))``, ``("html", raw)``, ``("table", (header, rows))``
    (headers read through :func:`physics.pages.columns.column`), ``("img", (path, caption))``,
    ``("pre", text)``."""
    from physics.pages.report import Report
    rep = Report(title)
    for kind, content in blocks:
        if kind in ("h2", "h3"):
            rep.heading(str(content), level=int(kind[1]))
        elif kind == "p":   # text, or (text, {words: address})
            text, links = content if isinstance(content, tuple) else (content, None)
            rep.paragraph(str(text), links=links)
        elif kind == "html":
            rep.raw(str(content))
        elif kind == "pre":
            rep.preformatted(str(content))
        elif kind == "img":
            path, caption = content
            rep.image(path, caption)
        elif kind == "table":
            header, rows = content
            rep.table([dict(zip(header, r["cells"] if isinstance(r, dict) else r)) for r in rows],
                      columns=[str(h) for h in header], missing="not applicable to this row")
        else:  # pragma: no cover - programming error
            raise ValueError(kind)
    return rep


def environment() -> dict:
    import torch

    return {"python": platform.python_version(), "torch": torch.__version__,
            "torch_threads": torch.get_num_threads(), "cpu_count": os.cpu_count(),
            "machine": platform.machine(), "platform": platform.platform()}
