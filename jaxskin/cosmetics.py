"""Cosmetic layers (Huang et al. 2013 §3.1): measured materials and thickness maps.

- A material is a calibrated JSON (`jaxskin calibrate` output, or a shipped example by
  name): S(λ) and K(λ) per mm, resampled onto a `spectral.Grid` linearly in log S, log K.
  A material that does not cover the grid is refused unless its file says how to extend it
  (`"extrapolate": "hold"` or `"linear"`); `Material.extrapolated` marks those bands.
- A thickness map (mm per texel, texture space) comes from named regions drawn on the
  mesh's UVs — ellipses and polygons, with a feathered edge — or from a greyscale image
  (value × a thickness scale), given as an array: files are read at the edge
  (`maps.read_grey`). UVs follow the OBJ convention: u right, v up.
- `layers` composes a stack per texel and band with the KM core: `km.Slab (H, W, n)`;
  zero thickness everywhere gives exactly R = 0, T = 1 (no makeup, no change).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from . import formats, km
from .io import InputError, data_dir, real_path
from .spectral import Grid

__all__ = ["Material", "check_material", "coverage", "ellipse_map", "extend", "image_map", "layers",
           "load_material", "material_path", "on_grid", "polygon_map", "shipped_materials"]


@dataclasses.dataclass(frozen=True, eq=False)
class Material:
    """`S`, `K (n,)` per mm on `grid`; `extrapolated (n,)`: bands outside the measurement."""

    name: str
    grid: Grid
    S: np.ndarray
    K: np.ndarray
    extrapolated: np.ndarray


def shipped_materials() -> list[str]:
    """The names of the example materials in data/materials."""
    return sorted(p.stem for p in (data_dir() / "materials").glob("*.json"))


def material_path(name_or_path, base=None) -> Path:
    """A material's file: a shipped example's, by name (no suffix); else the path, taken
    relative to `base` (default: the working directory)."""
    key = str(name_or_path)
    shipped = data_dir() / "materials" / f"{key}.json"
    if not Path(key).suffix and Path(key).name == key and shipped.is_file():  # a bare name
        return shipped
    return Path(key) if base is None else real_path(Path(base) / key)


def load_material(name_or_path, grid: Grid) -> Material:
    """A calibrated material by file or by the name of a shipped example, on `grid`.

    A material must cover the grid's wavelengths unless its file says how to extend it
    (`"extrapolate": "hold"` or `"linear"`, what `jaxskin calibrate --extrapolate` writes);
    otherwise `InputError` names the file and the range it covers.
    """
    path = material_path(name_or_path)
    if not path.exists():
        raise InputError(f"no such material file (shipped: {', '.join(shipped_materials())})",
                         path)
    f = formats.read_material(path)
    return on_grid(f, grid)


def check_material(path) -> None:
    """Read a material file and check that it covers the render grid (380–780 nm at any
    step) or says how to extend it; `InputError` otherwise. For checks before any work."""
    on_grid(formats.read_material(path), Grid())


def on_grid(f: formats.MaterialFile, grid: Grid) -> Material:
    """A material file's S, K resampled onto `grid`, linearly in log S, log K; outside the
    measured range as the file's `extrapolate` says, else an `InputError`."""
    g, wl = grid.wavelengths, f.wavelength_nm
    outside = (g < wl[0] - 1e-9) | (g > wl[-1] + 1e-9)
    if outside.any() and f.extrapolate is None:
        raise InputError(
            f"material '{f.name}' covers {wl[0]:g}-{wl[-1]:g} nm, not all of the render grid "
            f"{g[0]:g}-{g[-1]:g} nm; add \"extrapolate\": \"hold\" or \"linear\" to the file "
            "(or calibrate with --extrapolate) to extend it", f.path, key="wavelength_nm")
    logS, logK = (extend(g, wl, np.log(v), f.extrapolate or "hold") for v in (f.S, f.K))
    return Material(f.name, grid, np.exp(logS), np.exp(logK), outside)


def extend(x, xp, fp, how: str = "hold", span: float = 20.0):
    """`fp (n,)` at `xp` interpolated linearly to `x`; beyond `xp`'s ends held at the end
    values (`how="hold"`) or continued along the least-squares line through the points
    within `span` of each end (at least two; `how="linear"`)."""
    out = np.interp(x, xp, fp)
    if how == "linear":
        for end, beyond in ((xp[0], x < xp[0]), (xp[-1], x > xp[-1])):
            near = np.abs(xp - end) <= span
            if near.sum() < 2:
                near = np.zeros(len(xp), bool)
                near[[0, 1] if end == xp[0] else [-2, -1]] = True
            slope = np.polyfit(xp[near], fp[near], 1)[0]
            value = np.interp(end, xp, fp)
            out = np.where(beyond, value + slope * (x - end), out)
    return out


def _uv_grid(height: int, width: int):
    """Texel centres in (u, v), v up: row 0 is v = 1."""
    u = (np.arange(width) + 0.5) / width
    v = 1.0 - (np.arange(height) + 0.5) / height
    return np.meshgrid(u, v)


def _feather(inside_distance, feather):
    """1 inside, 0 outside, a linear ramp of width `feather` (uv units) across the edge."""
    if feather <= 0:
        return (inside_distance >= 0).astype(np.float64)
    return np.clip(0.5 + inside_distance / feather, 0.0, 1.0)


def ellipse_map(height, width, center, radii, thickness_mm, angle_deg=0.0, feather=0.0):
    """Thickness (mm) of an ellipse in UV space: `center (u, v)`, `radii (a, b)`, turned by
    `angle_deg`; `feather`: width of the soft edge in uv units."""
    u, v = _uv_grid(height, width)
    t = math.radians(angle_deg)
    du, dv = u - center[0], v - center[1]
    x = (math.cos(t) * du + math.sin(t) * dv) / radii[0]
    y = (-math.sin(t) * du + math.cos(t) * dv) / radii[1]
    rho = np.hypot(x, y)
    inside = (1.0 - rho) * min(radii)  # ≈ distance to the edge, in uv units
    return thickness_mm * _feather(inside, feather)


def polygon_map(height, width, points, thickness_mm, feather=0.0):
    """Thickness (mm) of a polygon `points [(u, v), ...]` in UV space, soft edge `feather`."""
    from matplotlib.path import Path as MplPath

    pts = np.asarray(points, np.float64)
    u, v = _uv_grid(height, width)
    q = np.stack([u.ravel(), v.ravel()], 1)
    inside = MplPath(pts).contains_points(q).reshape(u.shape)
    # Distance to the polygon's edges, signed: + inside.
    a, b = pts, np.roll(pts, -1, axis=0)
    ab = b - a
    t = np.clip(((q[:, None] - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-300), 0, 1)
    d = np.linalg.norm(q[:, None] - (a + t[..., None] * ab), axis=-1).min(axis=1)
    signed = np.where(inside.ravel(), d, -d).reshape(u.shape)
    return thickness_mm * _feather(signed, feather)


def image_map(image, height, width, scale_mm):
    """Thickness (mm) from a greyscale map `image (H', W')` in [0, 1] (`maps.read_grey`
    reads one from a file): value × `scale_mm`, resampled (nearest texel) to
    `(height, width)`; row 0 is the image's top (v = 1)."""
    img = np.asarray(image, np.float64)
    if img.ndim != 2:
        raise ValueError(f"expected a greyscale map (H, W), got shape {img.shape}")
    rows = (np.arange(height) + 0.5) * img.shape[0] / height
    cols = (np.arange(width) + 0.5) * img.shape[1] / width
    return scale_mm * img[rows.astype(int)][:, cols.astype(int)]


def layers(S, K, thickness):
    """The stack's `km.Slab`, per texel and band: `S, K (L, n)` (top layer first),
    `thickness (L, H, W)` mm. Differentiable in all three."""
    S, K, X = (jnp.asarray(a) for a in (S, K, thickness))
    R, T = km.layer(S[:, None, None, :], K[:, None, None, :], X[..., None])
    return km.stack(R, T)


def coverage(spec, vertex_uv: np.ndarray, height: int, width: int,
             image: np.ndarray | None = None) -> np.ndarray:
    """A layer's map `(H, W)` in [0, 1] from its `scene.LayerSpec`: its image (the array
    `image (H', W')` that `maps.read_grey` read from `spec.image`), or the union (maximum)
    of its ellipses and polygons, or 1 everywhere when it has neither. Regions are in
    texture coordinates (u right, v up; the mesh's UVs for the uv projection); polygons
    given by mesh vertices use `vertex_uv (V, 2)`, those vertices' coordinates."""
    if spec.image is not None:
        if image is None:
            raise ValueError(f"layer {spec.name!r} has an image ({spec.image}): pass its "
                             "array, maps.read_grey(spec.image)")
        return np.clip(image_map(image, height, width, 1.0), 0.0, 1.0)
    if not spec.ellipses and not spec.polygons:
        return np.ones((height, width))
    out = np.zeros((height, width))
    for center, radii, angle, feather in spec.ellipses:
        out = np.maximum(out, ellipse_map(height, width, center, radii, 1.0, angle, feather))
    for i, (points, vertices, feather) in enumerate(spec.polygons):
        if vertices is not None:
            if max(vertices) >= len(vertex_uv):
                raise InputError(f"vertex {max(vertices)} does not exist; the mesh has "
                                 f"{len(vertex_uv)} vertices",
                                 key=f"layer.{spec.name}.polygon[{i}].vertices")
            points = vertex_uv[list(vertices)]
        out = np.maximum(out, polygon_map(height, width, points, 1.0, feather))
    return out
