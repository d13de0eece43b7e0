"""Make the committed figure of the README and the docs' front page (a small PNG).

    python docs/figures/make_figures.py     # -> docs/figures/frequency_response.png
"""
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1]))       # the checkout's package when run from a clone
import physics  # noqa: E402


def main() -> int:
    f = np.logspace(-1, 2, 500)
    fig, (ax_mag, ax_ph) = plt.subplots(2, 1, figsize=(6.4, 4.0), sharex=True, dpi=100,
                                        gridspec_kw={"height_ratios": [2, 1]})
    for rh, colour in zip((40, 60, 80, 100), ("#b2182b", "#ef8a62", "#67a9cf", "#2166ac")):
        fr = physics.frequency_response("ipmc_pt_eg", "default", f, rh=rh)
        ax_mag.loglog(f, 1e3 * fr.magnitude, color=colour, label=f"RH {rh} %")
        ax_ph.semilogx(f, fr.phase_deg, color=colour)
    ax_mag.set_ylabel("tip deflection [mm/V]")
    ax_ph.set_ylabel("phase [°]")
    ax_ph.set_xlabel("frequency [Hz]")
    ax_mag.legend(frameon=False, loc="upper left", ncol=2)
    ax_mag.set_title("IPMC strip (thesis device ipmc_pt_eg), default effects", fontsize=10)
    for ax in (ax_mag, ax_ph):
        ax.grid(True, which="major", alpha=0.3)
    fig.tight_layout()
    out = HERE / "frequency_response.png"
    fig.savefig(out, metadata={"Software": None})
    print(f"wrote {out} ({out.stat().st_size // 1024} KB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
