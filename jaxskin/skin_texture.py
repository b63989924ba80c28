"""The files of a texture's skin maps (`jaxskin.skin_maps`): the texture read and checked,
the maps written as the 16-bit greyscale PNGs a scene loads, the skin mask, the
reproduced texture, a scene snippet that uses them, the report; and the inversion cached
by the texture's content for the scene key `skin.texture`.

A map's PNG holds the value divided by its scene scalar, the top of its range
(`SCALES`): `skin.melanin_fraction = 0.5` × `skin.melanin_fraction_image`,
`skin.haemoglobin = 0.1` × `skin.haemoglobin_image`, `skin.brightness = 2` ×
`skin.brightness_image`; 16 bits keep 1/655 of the smallest melanin fraction (0.005).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
from pathlib import Path

import numpy as np

from . import biophysical, maps
from .io import InputError, atomic_write
from .skin_maps import BRIGHTNESS, Fixed, Inversion

__all__ = ["MAP_FILES", "SCALES", "cache_beside", "cache_folder",
           "invert_texture", "output_names", "read_texture", "scene_snippet", "texture_digest",
           "texture_maps", "write_all", "write_report"]

# Each fitted map: its file suffix, the scene keys of its scalar and its image.
MAP_FILES = {"melanin": ("_melanin.png", "melanin_fraction", "melanin_fraction_image"),
             "haemoglobin": ("_haemoglobin.png", "haemoglobin", "haemoglobin_image"),
             "brightness": ("_brightness.png", "brightness", "brightness_image")}
SCALES = {"melanin": biophysical.RANGES["melanin"][1],
          "haemoglobin": biophysical.RANGES["haemoglobin"][1], "brightness": BRIGHTNESS[1]}


def read_texture(path, key=None, size: int | None = None, square: bool = False
                 ) -> tuple[np.ndarray, np.ndarray | None, list[str]]:
    """A colour texture: `(rgb (H, W, 3) display sRGB, alpha (H, W) or None, notes)`,
    checked first by `scan.check_texture` (`size`, `square`: its arguments; its notes are
    returned). An image whose pixels are all grey (no colour to invert) is an `InputError`;
    16-bit samples are kept, and an alpha channel marks its transparent texels as not
    skin."""
    from .scan import check_texture

    notes = list(check_texture(path, key=key, size=size, square=square).notes)
    rgb, alpha = maps.read_image(path, "colour texture", key=key)
    if np.all(rgb == rgb[..., :1]):
        raise InputError("expected a colour (RGB) texture; this one is grey: a skin's colour "
                         "is what the maps are fitted to", path, key=key)
    if alpha is not None and not (alpha <= 0.0).any():
        alpha = None
    return rgb, alpha, notes


def invert_texture(rgb, alpha=None, fixed: Fixed | None = None,
                   threshold: float | None = None) -> Inversion:
    """`skin_maps.invert` of a texture read by `read_texture`: its transparent texels
    (`alpha` 0) are not skin; `threshold`: the mask's ΔE2000 (default
    `skin_maps.SKIN_DE`)."""
    from . import skin_maps

    inv = skin_maps.invert(rgb, fixed=fixed)
    if threshold is not None:
        inv = inv._replace(skin=skin_maps.skin_mask(inv.de, threshold))
    if alpha is not None:
        inv = inv._replace(skin=inv.skin & (alpha > 0))
    return inv


def texture_digest(path) -> str:
    """The texture file's content hash (SHA-256, 16 hex digits): the cache's key."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()[:16]


def cache_folder(output_folder, texture) -> Path:
    """Where `skin.texture`'s inversion is kept: `<output>/skin_maps_<digest>/`."""
    return Path(output_folder) / f"skin_maps_{texture_digest(texture)}"


def scene_snippet(stem: str, fixed: Fixed, texture: str | None = None) -> str:
    """The TOML lines that render the maps `stem_*.png` (beside the snippet) as the
    biophysical skin under a scene's layers; with `texture` (its path as the snippet
    should name it), the texels outside the skin mask in the texture's own colour."""
    lines = ["# The biophysical skin of a texture, from `jaxskin skin-maps` (the maps are in",
             "# texture space: give the mesh whose UVs the texture was made for).",
             "[mesh]", '# file = "scan.obj"', 'projection = "uv"',
             "[material]", 'model = "biophysical"', "[skin]"]
    for name, (suffix, scalar, image) in MAP_FILES.items():
        lines += [f"{scalar} = {SCALES[name]:g}", f'{image} = "{stem}{suffix}"']
    lines += [f"{name} = {getattr(fixed, name):g}" for name in Fixed._fields]
    if texture is not None:
        lines += [f"colour_image = {json.dumps(texture)}  # the colour where the mask is 0",
                  f'mask_image = "{stem}_skin_mask.png"']
    lines += ["[spectral]", 'illuminant = "D65"  # the light the texture\'s colour is seen under']
    return "\n".join(lines) + "\n"


def output_names(stem: str, report: bool = True) -> dict[str, str]:
    """The files `write_all` writes for a texture `stem.png`: `{what: file name}`."""
    names = {**{k: f"{stem}{v[0]}" for k, v in MAP_FILES.items()},
             "mask": f"{stem}_skin_mask.png", "reproduced": f"{stem}_reproduced.png",
             "scene": f"{stem}_skin.toml"}
    if report:
        names["report"] = f"{stem}_skin_maps.png"
    return names


def write_all(inv: Inversion, texture, folder, stem: str, fixed: Fixed,
              paths: dict | None = None, report: bool = True,
              texture_path=None) -> dict[str, Path]:
    """Write the maps, mask, reproduction, snippet (and the report, with `texture (H, W,
    3)`) of `inv` into `folder` as `stem_*` (`output_names`); `paths` may give each file's
    path (a command's planned outputs); `texture_path`: the texture's file, which the
    snippet names (relative to `folder`) as the colour of the texels that are not skin.
    Returns `{what: path}`."""
    folder = Path(folder)
    paths = {k: Path(paths[k]) if paths and k in paths else folder / v
             for k, v in output_names(stem, report).items()}
    for name in MAP_FILES:
        maps.write_grey16(getattr(inv, name) / SCALES[name], paths[name])
    maps.write_grey16(inv.skin.astype(np.float64), paths["mask"])
    maps.write_image(inv.rgb, paths["reproduced"])
    with atomic_write(paths["scene"], "w") as fh:
        name = None
        if texture_path is not None:
            name = os.path.relpath(Path(texture_path).resolve(), folder.resolve())
            if name.startswith(os.path.join(os.pardir, os.pardir, os.pardir)):
                name = str(Path(texture_path).resolve())  # far away: named in full
        fh.write(scene_snippet(stem, fixed, name))
    if report:
        write_report(inv, texture, paths["report"])
    return paths


def write_report(inv: Inversion, texture, path) -> None:
    """The report PNG: texture, reproduction, the CIEDE2000 map, the skin mask, and the
    three maps (log colour scales), with the ΔE figures over the skin texels."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    skin = inv.skin
    de = inv.de[skin] if skin.any() else np.array([np.nan])
    fig, axes = plt.subplots(2, 4, figsize=(16, 8.6), constrained_layout=True)
    panels = [("texture", texture, None), ("reproduced from the maps", inv.rgb, None),
              ("ΔE2000 texture - reproduction", inv.de, (0.0, 5.0)),
              (f"skin mask (white: {skin.mean():.0%} of texels)", skin, (0, 1))]
    for ax, (title, img, lim) in zip(axes[0], panels, strict=True):
        if lim is None:
            ax.imshow(np.clip(img, 0, 1), interpolation="nearest")
        else:
            im = ax.imshow(img, cmap="magma" if title.startswith("ΔE") else "gray",
                           vmin=lim[0], vmax=lim[1], interpolation="nearest")
            if title.startswith("ΔE"):
                fig.colorbar(im, ax=ax, shrink=0.8)
        ax.set_title(title, fontsize=10)
    ranges = {**biophysical.RANGES, "brightness": BRIGHTNESS}
    for ax, name in zip(axes[1, :3], ("melanin", "haemoglobin", "brightness"), strict=True):
        im = ax.imshow(getattr(inv, name), cmap="viridis", norm=LogNorm(*ranges[name]),
                       interpolation="nearest")
        fig.colorbar(im, ax=ax, shrink=0.8)
        ax.set_title({"melanin": "melanin fraction", "haemoglobin": "haemoglobin (blood) "
                      "fraction", "brightness": "brightness"}[name], fontsize=10)
    ax = axes[1, 3]
    ax.hist(np.clip(inv.de.ravel(), 0, 10), bins=50, color="0.6", label="all texels")
    ax.hist(np.clip(de, 0, 10), bins=50, color="C3", label="skin texels")
    ax.set(xlabel="ΔE2000 (clipped at 10)", yscale="log")
    ax.set_title(f"skin ΔE2000: median {np.median(de):.2f}, p95 {np.percentile(de, 95):.2f}",
                 fontsize=10)
    ax.legend(fontsize=8)
    for a in axes.ravel()[:7]:
        a.set_xticks([])
        a.set_yticks([])
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=80)
    plt.close(fig)


_MEMO: dict = {}  # (texture digest, held values) → maps: one inversion per process
_CACHE: list = []  # the folder `cache_beside` names, while it is in force


@contextlib.contextmanager
def cache_beside(folder):
    """While in force, `texture_maps` keeps each inversion in `cache_folder(folder, ...)`
    (a command's output folder) and reads it from there on the next run."""
    _CACHE.append(Path(folder))
    try:
        yield
    finally:
        _CACHE.pop()


def texture_maps(path, held: tuple = ()) -> dict[str, np.ndarray]:
    """The maps of the texture `path` (scene key `skin.texture`): `{"melanin",
    "haemoglobin", "brightness": (H, W) values, "skin": (H, W) mask 0/1, "colour": (H, W, 3)
    display sRGB}`; `held`: `Fixed`'s values. Inverted once per process and texture
    content; under `cache_beside`, written to (and read again from) the output folder."""
    fixed = Fixed(*held)
    key = (texture_digest(path), fixed)
    if key in _MEMO:
        return _MEMO[key]
    folder = cache_folder(_CACHE[-1], path) / f"{'_'.join(f'{v:g}' for v in fixed)}" if (
        _CACHE) else None
    names = output_names("texture", report=False)
    rgb, alpha, _ = read_texture(path, key="skin.texture", square=True)
    if folder is not None and all((folder / n).is_file() for n in names.values()):
        out = {k: maps.read_grey(folder / names[k]) * SCALES[k] for k in MAP_FILES}
        out["skin"] = maps.read_grey(folder / names["mask"])
    else:
        inv = invert_texture(rgb, alpha, fixed)
        out = {k: getattr(inv, k) for k in MAP_FILES}
        out["skin"] = inv.skin.astype(np.float64)
        if folder is not None:
            folder.mkdir(parents=True, exist_ok=True)
            write_all(inv, rgb, folder, "texture", fixed, report=False)
    out["colour"] = rgb
    _MEMO[key] = out
    return out
