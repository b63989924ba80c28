"""The PNG report of a Kubelka–Munk calibration: data vs fit, S and K, colour swatches."""

from __future__ import annotations

import numpy as np

from jaxskin.io import atomic_write

from .km import KMFit
from .measurements import Measurement


def _shade(ax, wl, mask):
    """Shade runs of bands where `mask` is False."""
    step = np.median(np.diff(wl)) if wl.size > 1 else 1.0
    bad = ~mask
    start = None
    for i, b in enumerate(np.append(bad, False)):
        if b and start is None:
            start = i
        elif not b and start is not None:
            ax.axvspan(wl[start] - step / 2, wl[i - 1] + step / 2, color="0.85", lw=0, zorder=0)
            start = None


def write_report(m: Measurement, r: KMFit, path) -> None:
    """Write the report PNG for measurement `m` and its fit `r` to `path` (atomically)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    wl = m.wavelength_nm
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2), constrained_layout=True)
    ax = axes[0]
    _shade(ax, wl, r.identifiable)
    colours = plt.cm.viridis(np.linspace(0.15, 0.85, len(m.thickness_mm)))
    for X, R, Rf, c in zip(m.thickness_mm, m.R, r.R_fit, colours, strict=True):
        ax.plot(wl, R, "o", ms=3, color=c, label=f"R {X:g} mm measured")
        ax.plot(wl, Rf, "-", color=c, label="fit")
    ax.plot(wl, m.R_inf, "s", ms=3, color="C3", label="R∞ measured")
    ax.plot(wl, r.R_inf_fit, "-", color="C3", label="fit")
    ax.plot(wl, m.R_g, "--", color="k", lw=1, label="R_g (background)")
    ax.set(xlabel="wavelength (nm)", ylabel="reflectance", ylim=(0, None),
           title=f"{m.name}: data and fit (rmse {r.rmse:.2e})")
    # below the axes: inside, ten entries covered the data (the lipstick around 600 nm)
    ax.legend(fontsize=7, ncol=3, loc="upper center", bbox_to_anchor=(0.5, -0.16))

    ax = axes[1]
    _shade(ax, wl, r.identifiable)
    ax.semilogy(wl, r.S_per_mm, "-", color="C0", label="S fitted")
    ax.semilogy(wl, r.K_per_mm, "-", color="C1", label="K fitted")
    ax.semilogy(wl, r.S_closed, "x", ms=4, color="C0", alpha=0.6, label="S closed form")
    ax.semilogy(wl, r.K_closed, "x", ms=4, color="C1", alpha=0.6, label="K closed form")
    ax.set(xlabel="wavelength (nm)", ylabel="per mm",
           title="S and K (grey: not identifiable, S from neighbours)")
    ax.legend(fontsize=7)

    ax = axes[2]
    _shade(ax, wl, r.identifiable)
    for X, R, Rf, c in zip(m.thickness_mm, m.R, r.R_fit, colours, strict=True):
        ax.plot(wl, Rf - R, ".-", ms=3, lw=0.7, color=c, label=f"{X:g} mm")
    ax.plot(wl, r.R_inf_fit - m.R_inf, ".-", ms=3, lw=0.7, color="C3", label="R∞")
    ax.axhline(0, color="k", lw=0.5)
    for s in (-3 * r.noise, 3 * r.noise):
        ax.axhline(s, color="k", lw=0.5, ls=":")
    ax.set(xlabel="wavelength (nm)", ylabel="fit − measured",
           title=f"residuals ({r.steps} LM steps{'' if r.converged else ', NOT converged'})")
    ax.legend(fontsize=7)
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=110)
    plt.close(fig)
