"""What `jaxskin match` writes: the match's JSON record and its PNG report
(`jaxskin.fitting.match`)."""

from __future__ import annotations

import numpy as np

from jaxskin.io import atomic_write

from .match import GAMUT_DE, OBSERVERS, Components, Match, colour_name

__all__ = ["match_json", "write_report"]


def match_json(result: Match, comps: Components, target=None, spectrum=None, background=None,
               spectral_weight=None, starts=None, seed=None, seconds=None,
               densities=None) -> dict:
    """The `<TARGET>_match.json` document: `concentrations` (material name → volume
    fraction; by weight too, `concentrations_by_weight`, when the components' `densities`
    are given), `thickness_mm` for a film, `dE2000` (`colour`), the target's and match's
    CIELAB, their spectra on the fit's grid, and how the fit ran."""

    def floats(a):
        return None if a is None else [float(v) for v in np.asarray(a)]

    doc = {
        "target": str(target) if target is not None else {"Lab": floats(result.lab_target)},
        **({"spectrum": spectrum} if spectrum else {}),
        "concentrations": {n: float(c) for n, c in zip(result.names, result.concentrations,
                                                         strict=True)},
        "by": "volume fraction (two-constant Kubelka-Munk mixing of S, K per mm)",
        **_by_weight(result, densities),
        "components": {n: str(p) for n, p in zip(comps.names, comps.paths, strict=True)},
    }
    if result.thickness_mm is not None:
        doc["thickness_mm"] = result.thickness_mm
        doc["thickness"] = "fitted" if result.thickness_fitted else "given"
        doc["background"] = str(background)
        doc["hides_background"] = bool(result.hides_background)
    else:
        doc["opaque"] = True
    doc.update({
        "dE2000": result.dE2000,
        "in_gamut": bool(result.in_gamut),
        "colour": colour_name(result.observer),
        **({"saunderson": list(result.saunderson)} if result.saunderson else {}),
        **({"metamerism": result.metamerism} if result.metamerism else {}),
        "Lab_target": floats(result.lab_target),
        "Lab_match": floats(result.lab_match),
        **({"rms_reflectance": result.rms} if result.rms is not None else {}),
        "wavelength_nm": floats(result.wavelength_nm),
        **({"R_target": floats(result.R_target)} if result.R_target is not None else {}),
        "R_match": floats(result.R_match),
        "fit": {
            "method": "Levenberg-Marquardt (optimistix, float64) on softmax logits of the "
                      "concentrations (and log thickness); loss dE*ab^2 + W^2 (100 x RMS "
                      "reflectance difference)^2",
            "spectral_weight": spectral_weight, "starts": starts, "seed": seed,
            "converged": result.converged, "steps": result.steps, "loss": result.loss,
            **({"seconds": round(seconds, 3)} if seconds is not None else {}),
        },
    })
    return doc


def _by_weight(result: Match, densities) -> dict:
    """`concentrations_by_weight` and the `densities` they come from, if given."""
    if not densities:
        return {}
    rho = np.array([densities[n] for n in result.names])
    w = result.concentrations * rho / np.sum(result.concentrations * rho)
    return {"concentrations_by_weight": {n: float(v) for n, v in zip(result.names, w,
                                                                       strict=True)},
            "densities": dict(densities)}


def _srgb(lab, observer):
    import colour

    xyz = colour.Lab_to_XYZ(np.asarray(lab), colour.CCS_ILLUMINANTS[OBSERVERS[observer]]["D65"])
    return np.clip(colour.XYZ_to_sRGB(xyz), 0.0, 1.0)


def write_report(result: Match, comps: Components, path, title: str = "match") -> None:
    """`<TARGET>_match.png`: the target's and the match's spectra with the components'
    opaque reflectances; swatches of target and match (sRGB) and the recipe."""
    import jax
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jaxskin import km

    fig, (ax, side) = plt.subplots(1, 2, figsize=(12, 4.6), width_ratios=(2.2, 1),
                                   constrained_layout=True)
    wl = comps.wavelength_nm
    with jax.enable_x64(True):
        R_inf = np.asarray(km.r_inf(comps.S, comps.K))
    for i, n in enumerate(comps.names):
        ax.plot(wl, R_inf[i], ":", lw=1, color=f"C{i + 2}", label=f"{n} (opaque)")
    if result.R_target is not None:
        ax.plot(result.wavelength_nm, result.R_target, "k-", lw=2, label="target")
    ax.plot(result.wavelength_nm, result.R_match, "r--", lw=1.8, label="match")
    ax.set(xlabel="wavelength (nm)", ylabel="reflectance", ylim=(0, 1.02),
           title=f"{title}: ΔE2000 {result.dE2000:.3f} (D65, {result.observer}°)"
                 + ("" if result.in_gamut else f" — OUT OF GAMUT (> {GAMUT_DE:g})"))
    ax.legend(fontsize=7, loc="upper left")
    side.axis("off")
    for x, lab in ((0.0, result.lab_target), (0.52, result.lab_match)):
        side.add_patch(plt.Rectangle((x, 0.62), 0.48, 0.36, color=_srgb(lab, result.observer),
                                     transform=side.transAxes))
    side.text(0.24, 0.58, "target", ha="center", va="top", transform=side.transAxes)
    side.text(0.76, 0.58, "match", ha="center", va="top", transform=side.transAxes)
    lines = [f"{n}: {c:.4f}" for n, c in zip(result.names, result.concentrations, strict=True)]
    if result.thickness_mm is not None:
        lines.append(f"film {result.thickness_mm * 1000:.2f} µm "
                     f"({'fitted' if result.thickness_fitted else 'given'})")
    lt, lm = result.lab_target, result.lab_match
    lines += [f"target L* {lt[0]:.1f} a* {lt[1]:.1f} b* {lt[2]:.1f}",
              f"match  L* {lm[0]:.1f} a* {lm[1]:.1f} b* {lm[2]:.1f}"]
    if result.rms is not None:
        lines.append(f"RMS reflectance difference {result.rms:.4f}")
    for k, v in (result.metamerism or {}).items():
        lines.append(f"{k}: {v:.2f}")
    side.text(0.0, 0.48, "volume fractions\n" + "\n".join(lines), va="top", fontsize=9,
              family="monospace", transform=side.transAxes)
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=100)
    plt.close(fig)
