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


def as_rendered(wl, r: KMFit, extrapolate: str, x) -> tuple[np.ndarray, np.ndarray]:
    """S and K per mm of fit `r` (measured at `wl`) at wavelengths `x` as the renderer
    extends them (`jaxskin.cosmetics.extend`, in log S and log K)."""
    from jaxskin.cosmetics import extend

    return tuple(np.exp(extend(x, wl, np.log(v), extrapolate))
                 for v in (r.S_per_mm, r.K_per_mm))


def far_extrapolation(m, result, how, grid) -> list[str]:
    """Where `--extrapolate linear` carries S or K more than tenfold beyond the data (a
    500-600 nm file can take K from 2.4 to 0.003 per mm at 780 nm: said, not silent)."""
    wl = m.wavelength_nm
    if how != "linear":
        return []
    out = []
    ends = [(x, 0 if x < wl[0] else -1) for x in (grid[0], grid[-1])
            if x < wl[0] or x > wl[-1]]  # each grid end beyond the data, its nearest datum
    for x, i in ends:
        at = as_rendered(wl, result, how, np.array([x]))
        for name, measured, far in (("S", result.S_per_mm[i], at[0][0]),
                                    ("K", result.K_per_mm[i], at[1][0])):
            if not 0.1 <= far / measured <= 10:
                out.append(f"--extrapolate linear takes {name} from {measured:.3g} per mm at "
                           f"{wl[i]:g} nm to {far:.3g} at {x:g} nm ({far / measured:.3g}x): "
                           "see the report's dashed curves, or use --extrapolate hold")
    return out


def _labels(m: Measurement) -> list[str]:
    """A legend label per row of `m.R`: its thickness, and on a contrast card the part."""
    out = []
    for i, X in enumerate(m.thickness_mm):
        size = f"{X:g} mm" if m.thickness_known else "film"
        out.append(f"R {size} over {m.over[i]}" if m.is_card else f"R {size}")
    return out


def coverage_line(r: KMFit) -> str:
    """The coverage figures in one line (`coverage.coverage`): per film the contrast ratio
    and ΔE2000 over ASTM D2805's black and white, the card's measured ones, the hiding
    thickness."""
    cov = r.coverage or {}
    parts = []
    for f in cov.get("films", []):
        size = "film" if f["thickness_mm"] is None else f"{f['thickness_mm']:g} mm"
        text = f"{size}: CR {f['contrast_ratio']:.3f}, ΔE00 {f['delta_E2000']:.1f}"
        if "contrast_ratio_card" in f:
            text += (f" (on the card, measured: CR {f['contrast_ratio_card']:.3f}, ΔE00 "
                     f"{f['delta_E2000_card']:.1f})")
        parts.append(text)
    if "hiding_98_mm" in cov:
        x = cov["hiding_98_mm"]
        parts.append("98 % hiding at " + ("-" if x is None else f"{x:.3g} mm"))
    elif "hiding_98_films" in cov:
        x = cov["hiding_98_films"]
        parts.append("98 % hiding at " + ("-" if x is None else f"{x:.3g} x the film"))
    return ("; ".join(parts) + "  [ASTM D2805 black 0 / white 0.80, D65, 10°]") if parts else ""


def write_report(m: Measurement, r: KMFit, path, extrapolate: str | None = None) -> None:
    """Write the report PNG for measurement `m` and its fit `r` to `path` (atomically).
    Where `m` does not cover the render grid (380–780 nm), the S and K panel shows how the
    renderer will extend them (`extrapolate`: "hold" or "linear", dashed), or says that it
    will refuse the material (`extrapolate` None)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.legend_handler import HandlerTuple

    from jaxskin.spectral import Grid

    wl = m.wavelength_nm
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6), constrained_layout=True)
    fig.suptitle(coverage_line(r), fontsize=9)
    ax = axes[0]
    _shade(ax, wl, r.identifiable)
    colours = plt.cm.viridis(np.linspace(0.15, 0.85, len(m.thickness_mm)))
    labels_of = _labels(m)
    handles, labels = [], []  # one entry a curve: its measured points and its fit together
    for label, R, Rf, c in zip(labels_of, m.R, r.R_fit, colours, strict=True):
        handles.append((ax.plot(wl, R, "o", ms=3, color=c)[0], ax.plot(wl, Rf, "-", color=c)[0]))
        labels.append(label)
    if m.R_inf is not None:
        handles.append((ax.plot(wl, m.R_inf, "s", ms=3, color="C3")[0],
                        ax.plot(wl, r.R_inf_fit, "-", color="C3")[0]))
        labels.append("R∞")
    else:
        handles.append(ax.plot(wl, r.R_inf_fit, "-", color="C3")[0])
        labels.append("R∞ (fitted)")
    if m.is_card:
        handles.append(ax.plot(wl, m.R_g, "--", color="k", lw=1)[0])
        labels.append("card, black part")
        handles.append(ax.plot(wl, m.R_g_white, ":", color="k", lw=1)[0])
        labels.append("card, white part")
    else:
        handles.append(ax.plot(wl, m.R_g, "--", color="k", lw=1)[0])
        labels.append("R_g (background)")
    ax.set(xlabel="wavelength (nm)", ylabel="reflectance", ylim=(0, None),
           title=f"{m.name}: measured (marks), fit (lines); rmse {r.rmse:.2e}")
    # below the axes: inside, the entries covered the data (the lipstick around 600 nm)
    ax.legend(handles, labels, handler_map={tuple: HandlerTuple(ndivide=None)}, fontsize=7,
              ncol=3, loc="upper center", bbox_to_anchor=(0.5, -0.16))

    ax = axes[1]
    _shade(ax, wl, r.identifiable)
    ax.semilogy(wl, r.S_per_mm, "-", color="C0", label="S fitted")
    ax.semilogy(wl, r.K_per_mm, "-", color="C1", label="K fitted")
    start = "one film over black and white" if m.is_card else "R∞ and one film"
    ax.semilogy(wl, r.S_closed, "x", ms=4, color="C0", alpha=0.6,
                label=f"S from {start} (closed form)")
    ax.semilogy(wl, r.K_closed, "x", ms=4, color="C1", alpha=0.6,
                label=f"K from {start} (closed form)")
    grid = Grid().wavelengths
    if wl[0] > grid[0] or wl[-1] < grid[-1]:  # the renderer's grid reaches beyond the data
        if extrapolate is None:
            ax.text(0.5, 0.03, f"covers {wl[0]:g}-{wl[-1]:g} nm of the renderer's "
                    f"{grid[0]:g}-{grid[-1]:g}:\nrefused at render time without --extrapolate",
                    transform=ax.transAxes, ha="center", va="bottom", fontsize=8, color="C3")
        else:
            x = np.arange(min(grid[0], wl[0]), max(grid[-1], wl[-1]) + 0.5, 1.0)
            for v, c, name in zip(as_rendered(wl, r, extrapolate, x), ("C0", "C1"), "SK",
                                  strict=True):
                ax.semilogy(x, v, "--", lw=1, color=c,
                            label=f"{name} as rendered (--extrapolate {extrapolate})")
            label = "no data: extended"
            for lo, hi in ((x[0], wl[0]), (wl[-1], x[-1])):
                if hi > lo:
                    ax.axvspan(lo, hi, color="C1", alpha=0.08, lw=0, zorder=0, label=label)
                    label = None
    ax.set(xlabel="wavelength (nm)", ylabel="per mm" if r.thickness_known else
           "per film (S·X, K·X: thickness not given)",
           title="S and K (grey: not identifiable, S from neighbours)")
    ax.legend(fontsize=7)

    ax = axes[2]
    _shade(ax, wl, r.identifiable)
    for label, R, Rf, c in zip(labels_of, m.R, r.R_fit, colours, strict=True):
        ax.plot(wl, Rf - R, ".-", ms=3, lw=0.7, color=c, label=label.removeprefix("R "))
    if m.R_inf is not None:
        ax.plot(wl, r.R_inf_fit - m.R_inf, ".-", ms=3, lw=0.7, color="C3", label="R∞")
    ax.axhline(0, color="k", lw=0.5)
    for s, label in ((-3 * r.noise, "±3σ of the noise"), (3 * r.noise, None)):
        ax.axhline(s, color="k", lw=0.5, ls=":", label=label)
    ax.set(xlabel="wavelength (nm)", ylabel="fit − measured",
           title=f"residuals ({r.steps} fit iterations"
                 f"{'' if r.converged else ', NOT converged'})")
    ax.legend(fontsize=7)
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=110)
    plt.close(fig)
