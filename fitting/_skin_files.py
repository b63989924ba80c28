"""The files `jaxskin fit-skin` writes from a `fitting.skin.SkinFit`: the CSV of the fits and
the report PNG (re-exported by `fitting.skin`)."""

from __future__ import annotations

import numpy as np

from jaxskin import biophysical as bp
from jaxskin.io import atomic_write

__all__ = ["LOG_PARAMS", "specular_word", "write_csv", "write_report"]

# The parameters spanning decades: fitted in log space (`fitting.skin`), drawn on log axes.
LOG_PARAMS = ("melanin", "haemoglobin", "epidermis_mm", "scattering")


def write_csv(result, path) -> None:
    """`<spectra>_fit.csv` of a `SkinFit` `result`, one row per spectrum: name, the six
    parameters, rms, dE2000, converged, steps, then each parameter's linearised standard
    deviation (`<name>_sd`), the melanin–epidermis correlation, and `specular` (`included`
    or `excluded`: the instrument mode the model was fitted for)."""
    header = ["name", *bp.PARAMS, "rms", "dE2000", "converged", "steps",
              *(f"{p}_sd" for p in bp.PARAMS), "corr_melanin_epidermis", "specular"]
    mode = specular_word(result.specular)
    lines = [",".join(header)]
    for k, name in enumerate(result.names):
        values = [f"{result.params[p][k]:.6g}" for p in bp.PARAMS]
        sds = [f"{result.sd[p][k]:.3g}" for p in bp.PARAMS]
        corr = result.corr_melanin_epidermis[k]
        lines.append(",".join([_cell(name), *values, f"{result.rms[k]:.6g}",
                               f"{result.dE2000[k]:.4f}", str(bool(result.converged[k])).lower(),
                               str(int(result.steps[k])), *sds,
                               f"{corr:.4f}" if np.isfinite(corr) else "", mode]))
    with atomic_write(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")


def specular_word(specular: bool) -> str:
    """`included` (SCI) or `excluded` (SCE): the instrument mode as `--specular` spells it."""
    return "included" if specular else "excluded"


def _cell(text: str) -> str:
    """A name as a CSV cell: quoted where it holds a comma, a quote or a line break (inner
    quotes doubled), and led by `'` where it starts like a spreadsheet formula (`=`, `+`,
    `-`, `@`, a tab or a return: a spectrum named `=cmd|...` would run as one in a
    spreadsheet), as OWASP advises for CSV files."""
    if text[:1] in ("=", "+", "-", "@", "\t", "\r"):
        text = "'" + text
    if any(ch in text for ch in ',"\n\r'):
        text = '"' + text.replace('"', '""') + '"'
    return text


def write_report(result, path, samples: int = 6) -> None:
    """`<spectra>_fit.png`: measured vs fitted spectra for `samples` spectra spread over the ΔE2000
    ranking (the best, the worst and between), and histograms of every parameter and of
    ΔE2000."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m = len(result.names)
    order = np.argsort(result.dE2000)
    pick = sorted({int(order[round(q * (m - 1))]) for q in np.linspace(0, 1, min(samples, m))},
                  key=lambda k: result.dE2000[k])
    fig = plt.figure(figsize=(16, 8.5), constrained_layout=True)
    grid = fig.add_gridspec(2, max(len(pick), 7))
    for j, k in enumerate(pick):
        ax = fig.add_subplot(grid[0, j])
        ax.plot(result.wavelengths, result.measured[k], "k-", lw=1.5, label="measured")
        ax.plot(result.wavelengths, result.fitted[k], "r--", lw=1.2, label="fit")
        p = result.params
        ax.set_title(f"{result.names[k]}\nΔE00 {result.dE2000[k]:.2f}, rms "
                     f"{result.rms[k]:.4f}", fontsize=8)
        ax.text(0.03, 0.97, f"mel {p['melanin'][k]:.3f} eu {p['eumelanin'][k]:.2f}\n"
                f"hb {p['haemoglobin'][k]:.3f} sat {p['oxygenation'][k]:.2f}\n"
                f"epi {p['epidermis_mm'][k] * 1000:.0f} µm sc {p['scattering'][k]:.2f}",
                transform=ax.transAxes, fontsize=7, va="top")
        ax.set(xlabel="nm", ylim=(0, max(0.05, 1.1 * float(np.nanmax(result.measured[k])))))
        if j == 0:
            ax.set_ylabel("reflectance")
            ax.legend(fontsize=7, loc="lower right")
    hists = [(name, result.params[name]) for name in bp.PARAMS] + [("ΔE2000", result.dE2000)]
    for j, (name, v) in enumerate(hists):
        ax = fig.add_subplot(grid[1, j])
        lo, hi = bp.RANGES.get(name, (0.0, max(3.0, float(v.max()))))
        log = name in LOG_PARAMS
        bins = np.geomspace(lo, hi, 21) if log else np.linspace(lo, hi, 21)
        ax.hist(np.clip(v, lo, hi), bins=bins, color="C0" if name != "ΔE2000" else "C3")
        if log:
            from matplotlib.ticker import NullFormatter

            ax.set_xscale("log")
            ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_title(f"{name}: median {np.median(v):.3g}", fontsize=8)
        ax.tick_params(labelsize=7)
    fig.suptitle(f"fit-skin: {m} spectra, specular {specular_word(result.specular)} "
                 f"({'SCI' if result.specular else 'SCE'}), ΔE2000 median "
                 f"{np.median(result.dE2000):.2f}, max {result.dE2000.max():.2f}; rms median "
                 f"{np.median(result.rms):.4f}", fontsize=11)
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=90)
    plt.close(fig)
