"""Memory: what a render will need, against what this machine has, before it starts.

`render_bytes` is a model fitted to peak resident sizes measured with `/usr/bin/time -v`
on `jaxskin render` (2-core CPU, float32):

| run | peak |
|---|---|
| hand, texture 1024², image 256² | 0.64 GB |
| hand, texture 2048², image 256² | 1.23 GB |
| hand, texture 4096², image 256² | 4.27 GB |
| makeup (3 layers, 41 bands), texture 512², image 256² | 0.71 GB |
| makeup, texture 1024², image 256² | 1.78 GB |
| makeup (4 layers, 41 bands), texture 512² / 1024², image 256² | 0.68 / 1.78 GB |
| the same at 81 bands (5 nm), 1024² | 1.76 GB |
| face (no layers, 41 bands), 1024² | 0.83 GB |
| hand, texture 256², image 1024² × supersample 4 (4096² samples) | 4.19 GB |

which give 164, 182 and 227 bytes per texel at 1024², 2048² and 4096² (Blinn /
Lafortune; growing with the size, so the model takes 280); the cosmetics model adds a
fixed amount per texel, 1640 bytes with layers and 200 without (its spectral work runs in
chunks: the peak did not grow from 3 to 4 layers nor from 41 to 81 bands),
220 bytes per image sample, over 0.45 GB of JAX itself; the model gives 0.99-1.42x each
row (tests/test_cli.py checks it against this table). A sweep renders in vmapped
batches of `cluster.SWEEP_BATCH` (8) values, so its variable part counts once per value of
one batch. The model errs high rather than low;
it is a guard against runs that cannot fit, not a forecast.

A scene's maps (layer images, skin maps) are read one at a time, before the render, at
their own size: `read_bytes` of the largest is added (a 12000² grey PNG of 165 KB: 2.3 GB
to read; 4.5 GB before the reader kept grey maps grey and converted in place).
`maps.read_image` checks the same figure from the file's header before decoding any image.

Shadows (`light.shadows`) with the spectral models test k × k points per texel on the host
before the render (`shadow.texture_visibility`: k = 2 up to 1024², else 1), with a dozen
float64 arrays per point: measured again on 2026-12-07 (the rows above for the face and
makeup predate their shadows), face 1024² 2.57 GB (0.98 GB with `light.shadows = false`),
makeup 512² 1.08 GB and 1024² 2.58 GB: about 480 bytes a point over 0.58 GB. That step
and the render do not overlap, so the model takes the larger of the two: 0.15 GB + 520
bytes a point, or the texels' part (1.03-1.11x of those four).

A user's mesh adds its own part: a 50k-vertex, 100k-face UV grid (face-sized) and a
250k-vertex, 500k-face one, texture 1024², spectral skin with SSS, image 512² (supersample
2): 1.01 and 1.16 GB, about 360 bytes per face (the model takes 500: 1.22x and 1.24x); the
500k one with shadows 2.74 GB (1.19x); at 4096² 4.73 GB (1.90x: the texture-space
rasterization tests its candidates in chunks, and its peak no longer counts; before, 6.44
GB).

`fit_brdf_bytes` likewise, from `jaxskin fit-brdf` on the 4,000 shipped samples: 0.36 GB
(3 lobes, 8 starts), 1.05 GB (3 lobes, 64 starts), 1.94 GB (6 lobes, 64 starts), about 100
bytes per sample, channel, lobe parameter and start (the model takes 120: 1.08-1.28x).
"""

from __future__ import annotations

import os
import stat
import warnings

from .io import InputError

__all__ = ["available_bytes", "check_memory", "fit_brdf_bytes", "image_header", "maps_bytes",
           "mesh_faces", "read_bytes", "render_bytes"]

BASE = 0.45e9
PER_TEXEL = 280
COSMETICS_PER_TEXEL = (200, 1640)  # bare skin, with layers
PER_SAMPLE = 220
PER_FACE = 500
SHADOW_BASE = 0.15e9
PER_SHADOW_POINT = 520
FIT_BASE = 0.35e9
PER_BRDF_VALUE = 120
# Reading an image, per pixel: per channel (the decoded samples and their float64 copy) and
# beside them (the greyscale map and its clipped copy). Measured peaks of `maps.read_grey`
# (/usr/bin/time -v): grey 8000² 1.04 GB, 12000² 2.29 GB, RGB 8000² 2.54 GB, against 20 and
# 44 bytes a pixel here (1.1-1.3x).
READ_PER_CHANNEL, READ_PER_PIXEL = 12, 8


def render_bytes(config, count: int = 1) -> float:
    """Estimated peak bytes of rendering a `scene.SceneConfig` (`count` sweep values)."""
    texels = config.texture.size ** 2
    per_texel = PER_TEXEL
    sp = config.spectral
    if sp is not None:
        per_texel += COSMETICS_PER_TEXEL[bool(sp.layers)]
    width = config.image * config.supersample
    height = (config.image_height or config.image) * config.supersample
    texture_part = count * texels * per_texel
    if sp is not None and config.shadow is not None:
        k = 2 if texels <= 1024 * 1024 else 1  # shadow.texture_visibility's test points
        texture_part = max(texture_part, SHADOW_BASE + PER_SHADOW_POINT * k * k * texels)
    return (BASE + PER_FACE * mesh_faces(config.texture.mesh) + texture_part
            + count * width * height * PER_SAMPLE + maps_bytes(config))


def mesh_faces(name_or_path) -> int:
    """The triangles of a scene's mesh (loaded once per process: `mesh.load_mesh`); 0
    where it cannot be read, which the scene's checks then say."""
    from .mesh import load_mesh

    try:
        return len(load_mesh(name_or_path).faces)
    except InputError:
        return 0


def maps_bytes(config) -> float:
    """Peak bytes of reading the largest of the scene's image maps (0 without any; a file
    whose header cannot be read counts 0: its reader says what is wrong with it)."""
    from .scene import SKIN_MAPS

    sp = config.spectral
    if sp is None:
        return 0.0
    files = [layer.image for layer in sp.layers] + [sp.image_of(k) for k in SKIN_MAPS]
    peaks = [0.0]
    for file in files:
        try:
            header = None if file is None else image_header(file)
        except Exception:  # noqa: BLE001  (too many pixels for Pillow: the reader says so)
            header = None
        if header is not None:
            peaks.append(read_bytes(*header[:3]))
    return max(peaks)


def image_header(path) -> tuple[int, int, int, str] | None:
    """`(width, height, channels, Pillow mode)` of an image file from its header, its pixels
    not decoded; None for a file that is not regular (a FIFO would block) or that Pillow
    cannot open (imageio may still read it). Pillow's warning of a large image
    (`DecompressionBombWarning`) is not shown: the memory is checked from this instead;
    its error above twice its limit (`DecompressionBombError`) is raised."""
    from PIL import Image

    try:
        if not stat.S_ISREG(os.stat(path).st_mode):
            return None
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(path) as im:
                return im.width, im.height, len(im.getbands()), im.mode
    except Image.DecompressionBombError:
        raise
    except Exception:  # noqa: BLE001  (Pillow raises many kinds; imageio has its turn)
        return None


def read_bytes(width: int, height: int, channels: int) -> float:
    """Peak bytes of reading a `width` × `height` image of `channels` channels
    (`maps.read_image`, `maps.read_grey`)."""
    return float(width) * height * (READ_PER_CHANNEL * channels + READ_PER_PIXEL)


def fit_brdf_bytes(samples: int, lobes: int, starts: int) -> float:
    """Estimated peak bytes of fitting `lobes` Lafortune lobes (RGB) to `samples` samples
    from `starts` starts at once (the Jacobians of every start are held together)."""
    return FIT_BASE + PER_BRDF_VALUE * samples * 3 * (1 + 3 * lobes) * starts


def available_bytes() -> tuple[float, str]:
    """Memory available to a new allocation now, and where the figure comes from:
    `MemAvailable` in /proc/meminfo, else free physical pages (os.sysconf)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024, "MemAvailable in /proc/meminfo"
    except OSError:
        pass
    try:
        pages = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        return float(pages), "free physical memory (sysconf)"
    except (ValueError, OSError, AttributeError):
        return float("inf"), "unknown"


def check_memory(estimate: float, what: str, where=None,
                 hint: str = "use a smaller texture.size, camera.size, camera.supersample or "
                 "sweep") -> None:
    """An `InputError` naming the estimate and the limit when `estimate` does not fit."""
    limit, source = available_bytes()
    if estimate > limit:
        raise InputError(f"{what} needs about {estimate / 2**30:.1f} GiB of memory; "
                         f"{limit / 2**30:.1f} GiB is available ({source}); {hint}", where)
