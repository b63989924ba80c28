"""Write benchmarks/biophysical_swatches.png: the biophysical skin model over its range.

Left: flat swatches (D65, sRGB) over melanin fraction (columns, 0.005–0.5) and haemoglobin
fraction (rows, 0.001–0.1), the other parameters at `biophysical.DEFAULT`. Middle: the 100
NIST forearms sorted by lightness, each swatch split: the measured spectrum's colour above,
its fitted biophysical twin's below (the fit in
benchmarks/fit_skin_nist/nist_skin_reflectance_M38597_fit.csv, made by
`jaxskin fit-skin data/spectra/nist_skin_reflectance_M38597.csv -o benchmarks/fit_skin_nist`).
Bottom: the face scene rendered with `material.model = "biophysical"` across melanin.

    .venv/bin/python benchmarks/biophysical_swatches.py
"""

from __future__ import annotations

import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from common import save_figure  # noqa: E402

from jaxskin import biophysical as bp  # noqa: E402
from jaxskin import formats, render, spectral  # noqa: E402
from jaxskin.scene import scene_at_width  # noqa: E402

HERE = Path(__file__).resolve().parent
OUT = HERE / "biophysical_swatches.png"
FIT = HERE / "fit_skin_nist" / "nist_skin_reflectance_M38597_fit.csv"
MELANIN = np.geomspace(0.005, 0.5, 9)
HAEMOGLOBIN = np.array([0.001, 0.005, 0.01, 0.02, 0.05, 0.1])
FACES = np.geomspace(0.01, 0.5, 6)
SIZE = 96


def _display(R, grid):
    return np.clip(np.asarray(render.encode_srgb(np.asarray(R) @ grid.rgb_matrix)), 0, 1)


def main() -> None:
    grid = spectral.Grid(5)
    c = bp.chromophores(grid.wavelengths, formats.haemoglobin_table())
    m, h = np.meshgrid(MELANIN, HAEMOGLOBIN)
    swatches = _display(bp.reflectance(c, bp.DEFAULT._replace(melanin=m, haemoglobin=h)), grid)

    names, wl, R = formats.read_spectra(formats.data_dir() / "spectra" / formats.NIST_FILE)
    measured = _display(np.stack([np.interp(grid.wavelengths, wl, r) for r in R]), grid)
    with FIT.open() as fh:
        rows = {row["name"]: row for row in csv.DictReader(fh)}
    params = {p: np.array([float(rows[n][p]) for n in names]) for p in bp.PARAMS}
    twins = _display(bp.reflectance(c, bp.Skin(**params)), grid)
    order = np.argsort(-measured.mean(axis=1))
    pairs = np.stack([measured[order], twins[order]], axis=1)  # (100, 2, 3)
    nist = pairs.reshape(5, 20, 2, 3).transpose(0, 2, 1, 3).reshape(10, 20, 3)

    sc = scene_at_width("face", SIZE, ["material.model=biophysical", "sss.enabled=false"])
    arrays = render.prepare(sc.config).arrays

    def face(mel):
        return render.render_prepared(sc.config, {**sc.params, "skin.melanin_fraction": mel},
                                      arrays)

    faces = np.asarray(jax.jit(jax.vmap(face))(jnp.asarray(FACES, jnp.float32)))
    strip = np.clip(faces.transpose(1, 0, 2, 3).reshape(SIZE, -1, 3), 0, 1)

    fig = plt.figure(figsize=(13, 8.4), dpi=100, constrained_layout=True)
    top = fig.add_gridspec(2, 2, height_ratios=[1.15, 1])
    ax = fig.add_subplot(top[0, 0])
    ax.imshow(swatches, interpolation="nearest")
    ax.set_xticks(range(len(MELANIN)), [f"{v:.3g}" for v in MELANIN], fontsize=7)
    ax.set_yticks(range(len(HAEMOGLOBIN)), [f"{v:g}" for v in HAEMOGLOBIN], fontsize=7)
    ax.set(xlabel="skin.melanin_fraction", ylabel="skin.haemoglobin",
           title="biophysical model (others at their defaults), D65, sRGB")
    ax = fig.add_subplot(top[0, 1])
    ax.imshow(nist, interpolation="nearest")
    ax.set_xticks([])
    ax.set_yticks(np.arange(5) * 2 + 0.5, [f"{20 * i + 1}–{20 * i + 20}" for i in range(5)],
                  fontsize=7)
    ax.set_title("NIST forearms by lightness: measured (upper) / fitted model (lower)")
    ax = fig.add_subplot(top[1, :])
    ax.imshow(strip, interpolation="nearest")
    ax.set_xticks((np.arange(len(FACES)) + 0.5) * SIZE, [f"{v:.3g}" for v in FACES])
    ax.set_yticks([])
    ax.set(xlabel="skin.melanin_fraction (face, material.model = \"biophysical\")")
    save_figure(fig, OUT)


if __name__ == "__main__":
    main()
