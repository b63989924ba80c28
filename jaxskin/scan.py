"""A user's scan: the checks of its texture image, before any work.

`check_texture(path)` reads only what it must (the header, and the alpha channel where there
is one) and says in one line what is wrong with a texture that cannot be a skin's colour:
not a regular file, not an image, greyscale, CMYK, not square (where the texture is a UV
map's). What it can handle it returns in `TextureInfo.notes` for the caller to warn (16 bits
per channel, a palette image, an alpha channel, a texture resampled to the render's size).
`jaxskin skin-maps` and a scene's `skin.texture` call it (`skin_texture.read_texture`).
(The mesh's own checks, its size included, are `jaxskin.mesh`'s.)
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from .io import InputError

__all__ = ["MAX_TEXTURE", "TextureInfo", "check_texture"]

# The largest texture a render reads at full size: `texture.size`'s own maximum (the scene
# schema's). A larger scan texture is resampled to the scene's size, and the caller says so.
MAX_TEXTURE = 8192


@dataclasses.dataclass(frozen=True)
class TextureInfo:
    """What `check_texture` found: `width`, `height` (pixels), PIL's `mode` ('RGB', 'RGBA',
    'P'), `bits` per channel, `transparent` (the fraction of pixels whose alpha is 0: not
    skin; 0 without alpha) and `notes`: one line each about what the reader will do that
    the user should know (16 bits read, transparent texels, palette expanded, resampled)."""

    path: str
    width: int
    height: int
    mode: str
    bits: int
    transparent: float
    notes: tuple[str, ...] = ()


def _png_header(path: Path) -> tuple[int, int] | None:
    """(bit depth, colour type) from a PNG's IHDR, or None for another format (PIL reads a
    16-bit RGB PNG as 8-bit 'RGB' without a word, so the header is read here)."""
    with open(path, "rb") as fh:
        head = fh.read(33)
    if len(head) < 33 or head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        return None
    return head[24], head[25]


def check_texture(path, key: str | None = None, size: int | None = None,
                  square: bool = True) -> TextureInfo:
    """Check that `path` is a texture a skin's colour can be read from: an RGB image, square
    unless `square` is False (a photo given to `jaxskin skin-maps`; a UV map's texture is
    square as `texture.size` is); 16-bit, RGBA and palette images are handled and noted.
    `key` names the scene key or option in the error; `size` is the render's
    `texture.size`, for a note when the image is resampled to it.

    **Returns:** a `TextureInfo`. **Raises:** `InputError`, one line naming the file."""
    from PIL import Image

    path = Path(path)
    if not path.exists():
        raise InputError("no such file (expected the scan's texture image)", path, key=key)
    if not path.is_file():  # a FIFO would block the read for ever
        what = "is a folder" if path.is_dir() else "not a regular file"
        raise InputError(f"{what} (expected the scan's texture image)", path, key=key)
    png = _png_header(path)
    try:
        with Image.open(path) as im:
            width, height, mode = im.width, im.height, im.mode
            bits = 16 if (png and png[0] == 16) or mode.startswith("I;16") else (
                max(im.tag_v2.get(258, (8,))) if hasattr(im, "tag_v2") else 8)
            alpha = None
            if mode in ("RGBA", "LA", "PA") or (mode == "P" and "transparency" in im.info):
                alpha = im.convert("RGBA").getchannel("A")
    except Image.DecompressionBombError as e:
        raise InputError(f"too large to read as an image ({e})", path, key=key) from None
    except Exception as e:  # noqa: BLE001  (PIL raises many kinds; all mean "not an image")
        raise InputError(f"cannot read as an image ({e.__class__.__name__}: {e}); expected "
                         "a PNG, JPEG or TIFF texture", path, key=key) from None
    if mode == "CMYK":
        raise InputError("a CMYK image; expected an RGB (sRGB) texture: CMYK has no "
                         "single RGB without its printer's profile", path, key=key)
    if mode in ("1", "L", "LA", "I", "F") or (png and png[1] in (0, 4)):
        raise InputError(f"a greyscale image ({mode}); expected a colour (RGB) texture: "
                         "the skin's colour is read from it", path, key=key)
    if mode not in ("RGB", "RGBA", "P"):
        raise InputError(f"image mode {mode}; expected an RGB texture", path, key=key)
    if square and width != height:
        raise InputError(f"{width}x{height} pixels; expected a square texture (UVs span "
                         "it whole, and texture.size is square): pad or resample it to "
                         f"{max(width, height)}x{max(width, height)}", path, key=key)
    notes = []
    if bits > 8:
        notes.append(f"{path}: {bits} bits per channel: read at full depth")
    transparent = 0.0
    if alpha is not None:
        import numpy as np

        transparent = float(np.mean(np.asarray(alpha) == 0))  # as read_texture drops them
        notes.append(f"{path}: has an alpha channel: its transparent texels "
                     f"({transparent:.0%}) are not skin; the colour is read as it is elsewhere")
    if mode == "P":
        notes.append(f"{path}: a palette image; its colours are read as RGB")
    if size is not None and width != size:
        notes.append(f"{path}: {width}x{height} resampled to texture.size {size}")
    elif width > MAX_TEXTURE:
        notes.append(f"{path}: {width}x{height} is over {MAX_TEXTURE}; resampled to it")
    return TextureInfo(str(path), width, height, mode, bits, transparent, tuple(notes))
