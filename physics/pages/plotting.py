"""Plots shared by the commands (matplotlib, headless Agg backend, PNG written atomically)."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..io.fileio import atomic_path  # noqa: E402


def save(fig, path) -> None:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, bbox_inches="tight", format="png")
    plt.close(fig)


def legend_outside(ax, **kw) -> None:
    """The legend beside the axes (right of them), never over the data."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=kw.pop("fontsize", 8), loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0,
                  frameon=False, **kw)


def rh_axis(ax, levels, axis: str = "x") -> None:
    """An RH axis labelled by nominal level: ticks at the levels rounded to 1 % (a
    hygrometer's jitter never becomes a tick or an offset such as "+7e1"), at least 10 %
    of range shown."""
    nominal = sorted({float(round(v)) for v in levels if v is not None and np.isfinite(v)})
    if not nominal:
        return
    lo, hi = nominal[0], nominal[-1]
    pad = max(5.0, 0.05 * (hi - lo))
    ticks = nominal if len(nominal) <= 12 else None   # many levels: matplotlib's own ticks
    if axis == "x":
        if ticks:
            ax.set_xticks(ticks)
        ax.set_xlim(lo - pad, hi + pad)
        ax.set_xlabel("RH [%] (nominal level)")
    else:
        if ticks:
            ax.set_yticks(ticks)
        ax.set_ylim(lo - pad, hi + pad)
        ax.set_ylabel("RH [%] (nominal level)")
    ax.ticklabel_format(axis=axis, style="plain", useOffset=False)


def plain_log_axis(ax, axis: str = "y") -> None:
    """Tick labels of a log axis as plain numbers (0.5, 2, 10, 200; never 6×10⁰ or
    6e−01); over fewer than 2.5 decades the 2s and 5s are labelled too.  Call after plotting."""
    import math
    from matplotlib.ticker import FuncFormatter, NullFormatter
    a = ax.yaxis if axis == "y" else ax.xaxis
    lo, hi = ax.get_ylim() if axis == "y" else ax.get_xlim()
    a.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    if lo > 0 and math.log10(hi / lo) < 2.5:
        def minor(v, _):
            m = v / 10 ** math.floor(math.log10(v)) if v > 0 else 0
            return f"{v:g}" if round(m, 6) in (2.0, 5.0) else ""
        a.set_minor_formatter(FuncFormatter(minor))
    else:
        a.set_minor_formatter(NullFormatter())


#: Points per line beyond which a time plot draws the min–max envelope instead.
MAX_LINE_POINTS = 20_000


def envelope(t: np.ndarray, y: np.ndarray, max_points: int = MAX_LINE_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """(t, y) thinned for drawing: for more than ``max_points`` samples, the minimum and
    maximum of each of ``max_points // 2`` equal buckets in time order, so the drawn line
    covers the same band as the full one (peaks kept) at a bounded cost in memory."""
    t, y = np.asarray(t), np.asarray(y)
    n = y.size
    if n <= max_points:
        return t, y
    k = max(1, max_points // 2)
    edges = np.linspace(0, n, k + 1).astype(int)
    i_lo = edges[:-1] + np.array([np.argmin(y[a:b]) for a, b in zip(edges[:-1], edges[1:])])
    i_hi = edges[:-1] + np.array([np.argmax(y[a:b]) for a, b in zip(edges[:-1], edges[1:])])
    first = i_lo <= i_hi                                   # keep each bucket's two points in time order
    idx = np.column_stack([np.where(first, i_lo, i_hi), np.where(first, i_hi, i_lo)]).ravel()
    return t[idx], y[idx]


def plot_timeseries(t, channels: dict[str, tuple[np.ndarray, str]], path, title: str = "") -> None:
    """One panel per channel: ``{label: (values, unit)}``."""
    fig, axes = plt.subplots(len(channels), 1, figsize=(8, 2.1 * len(channels)), sharex=True, squeeze=False)
    for ax, (label, (y, unit)) in zip(axes[:, 0], channels.items()):
        ax.plot(*envelope(t, y), lw=0.8)
        ax.set_ylabel(f"{label} [{unit}]")
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    if title:
        axes[0, 0].set_title(title)
    save(fig, path)


def plot_bode(freq, responses: dict[str, np.ndarray], path, unit: str = "mm/V", title: str = "",
              coherence: np.ndarray | None = None) -> None:
    """Bode magnitude and phase of complex responses ``{label: H(freq)}`` in m/V (plotted in
    ``unit``: mm/V or m/V); optional coherence on the same frequencies."""
    curves = {label: (np.asarray(freq), np.asarray(H), {}) for label, H in responses.items()}
    plot_bode_curves(curves, path, unit=unit, title=title,
                     coherence=None if coherence is None else (np.asarray(freq), coherence))


def plot_bode_curves(curves: dict, path, *, unit: str = "mm/V", coherence=None, bounds=None,
                     title: str = "") -> None:
    """Bode magnitude and phase [deg] of several complex responses [m/V] on their own
    frequencies: ``curves`` maps label → (freq [Hz], H, matplotlib style dict).  Optional
    coherence panel (freq, γ²) and magnitude confidence bounds (freq, lo, hi) [m/V]."""
    scale = {"mm/V": 1e3, "m/V": 1.0, "um/V": 1e6}[unit]
    rows = 3 if coherence is not None else 2
    fig, ax = plt.subplots(rows, 1, figsize=(7.5, 2.5 * rows), sharex=True)
    for label, (f, H, style) in curves.items():
        ok = np.isfinite(H) & (f > 0)
        if not ok.any():
            continue
        ax[0].loglog(f[ok], scale * np.abs(H[ok]), label=label, **style)
        ax[1].semilogx(f[ok], np.degrees(np.unwrap(np.angle(H[ok]))), label=label, **style)
    if bounds is not None:
        fb, lo, hi = bounds
        ok = np.isfinite(lo) & np.isfinite(hi) & (fb > 0)
        ax[0].fill_between(fb[ok], scale * np.maximum(lo[ok], 1e-30), scale * hi[ok], color="C0", alpha=0.15,
                           lw=0, label="95 % bounds")
    ax[0].set_ylabel(f"|H| [{unit}]")
    ax[1].set_ylabel("phase [°]")
    if coherence is not None:
        fc, coh = coherence
        ax[2].semilogx(fc[fc > 0], coh[fc > 0], color="k", lw=0.7)
        ax[2].set_ylabel("coherence γ²")
        ax[2].set_ylim(0, 1.05)
    for a in ax:
        a.grid(alpha=0.3, which="both")
    legend_outside(ax[0])
    ax[-1].set_xlabel("frequency [Hz]")
    if title:
        ax[0].set_title(title, fontsize=10)
    save(fig, path)
