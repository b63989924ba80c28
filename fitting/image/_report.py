"""The fit's report PNG (matplotlib)."""

from __future__ import annotations

import numpy as np

from jaxskin.io import atomic_write

from ._solve import ImageFit


def write_report(result: ImageFit, target, w, maps: dict, path, title: str = "") -> None:
    """The report PNG: target, fit, |residual| heat map, loss against step, and each fitted
    map (`maps`: key → (values `(H, W)` in the scalar's units, texture mask, unit name))."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt


    ncol = 4
    rows = 1 + -(-len(maps) // ncol)
    fig, axes = plt.subplots(rows, ncol, figsize=(4 * ncol, 3.9 * rows), squeeze=False,
                             constrained_layout=True)
    fit_image = np.clip(result.image, 0, 1)
    axes[0, 0].imshow(np.clip(target, 0, 1))
    axes[0, 0].set_title("target")
    axes[0, 1].imshow(fit_image)
    axes[0, 1].set_title(f"fit ({result.solver}, {result.steps} steps, {result.seconds:.0f} s)")
    err = np.abs(fit_image - np.asarray(target)).mean(axis=-1)
    err = np.where(np.asarray(w) > 0, err, np.nan)
    im = axes[0, 2].imshow(err, cmap="inferno", vmin=0)
    axes[0, 2].set_title(f"|fit − target| (RMS {result.rms:.4f})")
    fig.colorbar(im, ax=axes[0, 2], shrink=0.8)
    ax = axes[0, 3]
    ax.semilogy(np.arange(1, len(result.history) + 1), result.history)
    finite = [v for v in result.history if np.isfinite(v) and v > 0]
    # At least a decade shown: over less, every tick of a flat loss reads "4.52176×10⁻⁴".
    if finite and max(finite) < 10 * min(finite):
        ax.set_ylim(min(finite) / 4, max(finite) * 4)
    ax.set_xlabel("step")
    ax.set_ylabel("loss")
    ax.set_title("loss")
    ax.grid(alpha=0.3)
    for a in axes[0, :3]:
        a.set_axis_off()
    titles = []
    for i, (key, (values, tmask, unit)) in enumerate(maps.items()):
        a = axes[1 + i // ncol, i % ncol]
        im = a.imshow(np.where(tmask, values, np.nan), cmap="viridis")
        # Key and unit on two lines: on one, "skin.melanin_fraction_map (skin.melanin_fraction)"
        # is wider than its panel and cut off at the figure's left edge.
        titles.append((a, a.set_title(f"{key}\n({unit})")))
        a.set_axis_off()
        fig.colorbar(im, ax=a, shrink=0.8)
    for j in range(len(maps), (rows - 1) * ncol):
        axes[1 + j // ncol, j % ncol].set_axis_off()
    if title:
        fig.suptitle(title)
    if titles:  # a line still wider than its panel (a layer's name is the user's): smaller
        fig.canvas.draw()  # lays the panels out, so their widths are known
        for a, t in titles:
            over = t.get_window_extent().width / a.get_window_extent().width
            if over > 1:
                t.set_fontsize(t.get_fontsize() / over)
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=90)
    plt.close(fig)
