"""Plots shared by the commands (matplotlib, headless Agg backend, PNG written atomically)."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .fileio import atomic_path  # noqa: E402


def save(fig, path) -> None:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, bbox_inches="tight", format="png")
    plt.close(fig)


def plot_timeseries(t, channels: dict[str, tuple[np.ndarray, str]], path, title: str = "") -> None:
    """One panel per channel: ``{label: (values, unit)}``."""
    fig, axes = plt.subplots(len(channels), 1, figsize=(8, 2.1 * len(channels)), sharex=True, squeeze=False)
    for ax, (label, (y, unit)) in zip(axes[:, 0], channels.items()):
        ax.plot(t, y, lw=0.8)
        ax.set_ylabel(f"{label} [{unit}]")
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    if title:
        axes[0, 0].set_title(title)
    save(fig, path)


def plot_bode(freq, responses: dict[str, np.ndarray], path, unit: str = "m/V", title: str = "",
              coherence: np.ndarray | None = None) -> None:
    """Bode magnitude and phase of complex responses ``{label: H(freq)}``; optional coherence."""
    rows = 3 if coherence is not None else 2
    fig, axes = plt.subplots(rows, 1, figsize=(7, 2.4 * rows), sharex=True)
    for label, H in responses.items():
        axes[0].loglog(freq, np.abs(H), label=label)
        axes[1].semilogx(freq, np.degrees(np.unwrap(np.angle(H))), label=label)
    axes[0].set_ylabel(f"|H| [{unit}]")
    axes[1].set_ylabel("phase [deg]")
    if coherence is not None:
        axes[2].semilogx(freq, coherence, color="k", lw=0.8)
        axes[2].set_ylabel("coherence")
        axes[2].set_ylim(0, 1.05)
    for ax in axes:
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=8)
    axes[-1].set_xlabel("frequency [Hz]")
    if title:
        axes[0].set_title(title)
    save(fig, path)
