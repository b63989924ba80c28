"""jaxskin: differentiable rendering of human skin and cosmetics in JAX.

The module map, one line per module, by layer; a layer imports only the layers above it and
the application (last) is imported by none (tests/test_architecture.py checks both, and
that this map names every module).

Geometry (Bando 2001 §3.1–3.2):

- `mesh`: body-part meshes, their normals and UVs, the built-in ones.
- `fields`: direction fields edited on the mesh (inverse-distance weighting).
- `projection`: texture space: planar, cylindrical or the mesh's own UVs.
- `raster`: the one rasterizer: triangle ids and barycentrics, differentiable interpolation.
- `view`: camera views: rasterize from a camera, sample the texture-space result.
- `shadow`: shadow maps of a parallel light.
- `texture`: a scene's texture-space stage (its own `TextureConfig`): fields, furrows, bumps.

Furrows (Bando 2001 §3.3, §4.1):

- `wrinkles`: the furrow height field, grown furrow by furrow.
- `lockstep`: the same furrows grown in lockstep, the parallel program.
- `furrow_stats`: what the two furrow programs must share, measured.
- `bump`: bump-mapped normals (eq. 4.10).

Optics (Bando 2001 §4.2; Huang et al. 2013):

- `km`: Kubelka–Munk layers and their composition (`Slab`).
- `spectral`: wavelength grids, illuminants, spectra → colour.
- `skin`: measured skin reflectance with a melanin control.
- `biophysical`: the two-layer biophysical skin (melanin, haemoglobin).
- `skin_maps`: an sRGB texture inverted into the biophysical skin's maps, and its mask.
- `cosmetics`: cosmetic layers: measured materials and thickness maps.
- `mixture`: pigments in a base: the two-constant Kubelka–Munk mixing rule.
- `sss`: subsurface scattering, the six-Gaussian skin profile.
- `shading`: one model per module: `shading.blinn`, `shading.lafortune`, `shading.kelemen`
  and `shading.layered` (KM layers over skin with SSS and per-layer specular).
- `precision`: float32 products at full precision on every device.
- `vectors`: dot products and unit vectors over a last axis of three, written out (fast on CPU).
- `samples`: the view's samples on the mesh as a list (Blinn and Lafortune shade only those).
- `linear`: a linear map with a transpose written by hand.

Pipeline:

- `render`: `render(config, params)`, the pure function of a scene.
- `skin_texels`: the cosmetics model's skin per texel: its arrays, maps and reflectance.
- `render_args`: what `render` is given, checked (keys, shapes, ranges, one dtype).
- `batch`: a render's units of work: an image, its maps, a sweep's padded batch.
- `checks`: what a scene passes before any render (memory, files, values).
- `resources`: memory estimates against what the machine has.
- `compile_cache`: JAX's persistent compilation cache for commands and workers.
- `skin_grid`: the melanin × blood grid of small renders (the docs' picture).

Files (read and written at the edge):

- `scene`: TOML scenes → a hashable config and differentiable parameters; writing them.
- `formats`: every table and document read or written: CSV, JSON, BRDF and material
  files, spectra.
- `maps`: images: renders as PNG or OpenEXR, height and normal maps, layer maps read.
- `export`: the mesh and its textures as GLB.
- `skin_texture`: a texture's skin maps as files: read, written, reported.
- `io`: `InputError`, atomic writes, the shipped data folder.
- `scan`: a user scan's texture image, checked (square 8-bit RGB; alpha and palette said).
- `outputs`: output folders and safe file names.
- `data`: the shipped meshes, scenes, spectra, materials, measurements and BRDF samples.

Fitting (`jaxskin.fitting`, optimistix; the repository's `fitting/`):

- `fitting`: the fits' package.
- `fitting.measurements`: the spectroradiometer measurement CSV.
- `fitting.km`: S(λ), K(λ) of a cosmetic from its measurements.
- `fitting.cards`: contrast cards (drawdowns): a film over a black and a white background.
- `fitting.coverage`: contrast ratio, 98 % hiding thickness, ΔE2000 over black vs white.
- `fitting.brdf`: Lafortune lobes from BRDF samples.
- `fitting.skin`: the biophysical skin from reflectance spectra.
- `fitting.image`: scene values and texture maps from a target image.
- `fitting.report`: the calibration report (PNG).
- `fitting.match`: colour matching: a mixture's concentrations (and film) for a target.
- `fitting.match_report`: the match's JSON record and PNG report.

Application:

- `cli`: the `jaxskin` command, one module per command.
- `editor`: the browser editor's session and HTTP API (`jaxskin edit`).
- `cluster`: a command's units of work on a Dask cluster (`--cluster`).

Everything numeric follows the dtype of its inputs; rendering defaults to float32
(`jaxskin.DEFAULT_DTYPE`), fitting (`fitting`) runs in float64.
"""

import importlib as _importlib

from .io import InputError

__version__ = "0.1.0"

__all__ = ["DEFAULT_DTYPE", "InputError", "km", "spectral", "__version__"]


def __getattr__(name: str):
    """`km`, `spectral` and `DEFAULT_DTYPE` (float32) on first use: importing the package
    does not import JAX (about a second), so that the `jaxskin` command can take SIGINT
    from its first moment (`_console`)."""
    if name in ("km", "spectral"):
        return _importlib.import_module(f".{name}", __name__)
    if name == "DEFAULT_DTYPE":
        import jax.numpy as jnp

        return jnp.float32
    raise AttributeError(f"module 'jaxskin' has no attribute {name!r}")


def __dir__():
    return sorted({*globals(), "DEFAULT_DTYPE", "km", "spectral"})
