"""Reading and writing images, at the edge: renders as 8- or 16-bit PNG (RGB or RGBA) or
linear OpenEXR, 16-bit height, normal map, and the field picture (fig. 3.4); the one image
reader (`read_image`, and `read_grey` for the greyscale maps a scene loads), which the
optics modules never call: they receive its arrays."""

from __future__ import annotations

import os
import struct
import tempfile
import warnings
import zlib
from pathlib import Path

import numpy as np

from .io import InputError, atomic_write

__all__ = ["CONVERTED_MODES", "FORMATS", "REFUSED_MODES", "exr_available", "image_bytes",
           "png16_bytes", "png_bytes", "quantize", "read_exr", "read_grey", "read_image",
           "write_exr", "write_field_plot", "write_grey16", "write_height", "write_image",
           "write_normals", "write_render"]

FORMATS = ("png", "png16", "exr")


def png_bytes(image: np.ndarray) -> bytes:
    """A PNG file's bytes of `image` (`(H, W)`, `(H, W, 3)` or `(H, W, 4)` uint8, or `(H, W)`
    uint16, the height map): Pillow's, with its defaults, called directly (the bytes
    imageio's `imwrite` gives, in half the time: 73 against 142 ms for the 512² makeup
    face)."""
    import io

    from PIL import Image

    out = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(image)).save(out, format="PNG")
    return out.getvalue()


def _write(path, data: bytes) -> None:
    with atomic_write(path, "wb") as fh:
        fh.write(data)


def write_image(image, path, bits: int = 8) -> None:
    """A PNG of display values in [0, 1] (clipped), `(H, W, 3)` RGB or `(H, W, 4)` RGBA
    (straight alpha, as PNG defines it), 8 or 16 bits per channel."""
    _write(path, image_bytes(image, bits))


def image_bytes(image, bits: int = 8) -> bytes:
    """The PNG file `write_image` writes, as bytes (the editor sends these to the page),
    tagged sRGB (`_srgb`): its values are display values."""
    if bits not in (8, 16):
        raise ValueError(f"bits must be 8 or 16, got {bits}")
    if bits == 8:
        return _srgb(png_bytes(quantize(image, 8)))
    return _srgb(png16_bytes(quantize(image, 16)))


def _srgb(png: bytes) -> bytes:
    """`png` with an sRGB chunk (rendering intent 0, perceptual) and the gAMA chunk PNG 1.2
    pairs with it (1/2.2, for decoders without sRGB) right after IHDR: a render's values
    are sRGB-encoded, and untagged a colour-managed viewer would have to guess. Maps
    that hold data (heights, normals, thickness) stay untagged."""
    at = 8 + 25  # the signature, then IHDR: length, type, 13 bytes, CRC
    if png[12:16] != b"IHDR":
        raise ValueError("not a PNG with IHDR first")
    return (png[:at] + _chunk(b"sRGB", b"\x00") + _chunk(b"gAMA", struct.pack(">I", 45455))
            + png[at:])


def _chunk(kind: bytes, body: bytes) -> bytes:
    """One PNG chunk: length, type, body, CRC of type and body."""
    crc = zlib.crc32(kind + body) & 0xFFFFFFFF
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", crc)


def quantize(image, bits: int = 8) -> np.ndarray:
    """Display values in [0, 1] (clipped) as the 8- or 16-bit samples a PNG holds."""
    image = np.clip(np.asarray(image, np.float64), 0.0, 1.0)
    top, kind = (255, np.uint8) if bits == 8 else (65535, np.uint16)
    return np.round(image * top).astype(kind)


def png16_bytes(image) -> bytes:
    """A 16-bit PNG of `image (H, W)`, `(H, W, 3)` or `(H, W, 4)` uint16 (grey, RGB,
    RGBA), written here (PNG 1.2: big-endian samples, filter 0, one zlib stream) because
    Pillow writes 16 bits for grey only."""
    image = np.asarray(image, np.uint16)
    H, W = image.shape[:2]
    C = 1 if image.ndim == 2 else image.shape[2]
    colour_type = {1: 0, 3: 2, 4: 6}[C]
    rows = image.astype(">u2").reshape(H, W * C).view(np.uint8)
    data = np.concatenate([np.zeros((H, 1), np.uint8), rows], axis=1).tobytes()

    header = struct.pack(">IIBBBBB", W, H, 16, colour_type, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", header)
            + _chunk(b"IDAT", zlib.compress(data, 6)) + _chunk(b"IEND", b""))


def png16_colour(data: bytes) -> np.ndarray | None:
    """The samples `(H, W, 3 or 4)` uint16 of a 16-bit RGB or RGBA PNG (`data`: the file's
    bytes), or None for any other file: Pillow, under imageio, reads these as 8 bits (the
    low byte dropped), so they are decoded by pypng (pure Python: about 3 s for 1024² of
    Paeth-filtered rows, yet quicker than a NumPy decoder of the filters, about 14 s)."""
    if data[:8] != b"\x89PNG\r\n\x1a\n" or data[12:16] != b"IHDR" or len(data) < 29:
        return None
    depth, colour = data[24], data[25]
    if depth != 16 or colour not in (2, 6):
        return None
    import png

    W, H, rows, info = png.Reader(bytes=data).asDirect()
    C = info["planes"]
    return np.vstack([np.asarray(r, np.uint16) for r in rows]).reshape(H, W, C)


def exr_available() -> bool:
    """Whether the OpenEXR bindings (the `exr` extra) are installed."""
    try:
        import OpenEXR  # noqa: F401
    except ImportError:
        return False
    return True


def write_exr(rgba, path) -> None:
    """A linear OpenEXR `(H, W, 4)` float32 RGBA (premultiplied alpha, OpenEXR's
    convention; primaries and white of sRGB/Rec. 709, the format's default), ZIP
    compressed. Written by the Academy Software Foundation's `OpenEXR` bindings, beside the
    target and renamed, as every output."""
    import OpenEXR

    rgba = np.asarray(rgba, np.float32)
    if rgba.ndim != 3 or rgba.shape[-1] != 4:
        raise ValueError(f"expected an (H, W, 4) RGBA image, got shape {rgba.shape}")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    channels = {c: np.ascontiguousarray(rgba[..., i]) for i, c in enumerate("RGBA")}
    with tempfile.TemporaryDirectory() as tmp:  # the bindings write to a file name
        name = os.path.join(tmp, "image.exr")
        with OpenEXR.File(header, channels) as f:
            f.write(name)
        with open(name, "rb") as fh:
            _write(path, fh.read())


def read_exr(path) -> np.ndarray:
    """The `(H, W, 4)` float32 RGBA of an OpenEXR file `write_exr` wrote."""
    import OpenEXR

    with OpenEXR.File(str(path), separate_channels=True) as f:
        channels = f.channels()
        return np.stack([channels[c].pixels for c in "RGBA"], axis=-1).astype(np.float32)


def _a(what: str) -> str:
    return f"{'an' if what[:1] in 'aeiou' else 'a'} {what}"


def _max_pixels() -> str:
    """Pillow's limit on an image's pixels (its guard against decompression bombs)."""
    from PIL import Image

    return f"{Image.MAX_IMAGE_PIXELS * 2:,}" if Image.MAX_IMAGE_PIXELS else "unbounded"


# Pillow modes whose channels are not grey or R, G, B (A): imageio hands over a CMYK JPEG's
# C, M, Y, K as R, G, B and alpha. CMYK and YCbCr are converted to RGB as Pillow converts
# them; LAB and HSV are refused (Pillow's conversion of LAB is not colour-managed).
CONVERTED_MODES, REFUSED_MODES = ("CMYK", "YCbCr"), ("LAB", "HSV")

def _decode(path, what: str, key) -> np.ndarray:
    """The image's samples `(H, W, C)` float64 (integers at the full scale of their type),
    checked: a regular, readable 2-D image of 1-4 channels of finite values, whose reading
    fits in memory (checked from its header, before decoding)."""
    import imageio.v3 as iio
    from PIL import Image

    from . import resources
    from .io import check_regular

    if not Path(path).exists():
        raise InputError(f"no such file (expected {_a(what)})", path, key=key)
    if Path(path).is_dir():
        raise InputError(f"is a folder (expected {_a(what)} file)", path, key=key)
    try:  # a FIFO would block the open below; a device never ends
        check_regular(path, f"{_a(what)} file")
    except InputError as e:
        raise InputError(e.message, path, key=key) from None
    try:
        header = resources.image_header(path)
        if header is not None:
            w, h, channels, _ = header
            resources.check_memory(resources.read_bytes(w, h, channels), f"reading {_a(what)} of "
                                   f"{w}x{h} pixels", path, hint="save it at a smaller size")
            if header[3] in REFUSED_MODES:
                raise InputError(f"{_a(header[3])} image (its channels are not R, G, B): save "
                                 f"it as RGB or greyscale (expected {_a(what)})", path)
        with open(path, "rb") as fh:
            img = png16_colour(fh.read())
        if img is None and header is not None and header[3] in CONVERTED_MODES:
            with Image.open(path) as im:
                img = np.asarray(im.convert("RGB"))
        if img is None:
            with warnings.catch_warnings():  # counted above: not Pillow's own line
                warnings.simplefilter("ignore", Image.DecompressionBombWarning)
                img = np.asarray(iio.imread(path))
    except InputError as e:
        raise InputError(e.message, e.path, key=key) from None
    except Exception as e:  # noqa: BLE001  (imageio raises many kinds; all mean unreadable)
        why = (e.strerror if isinstance(e, OSError) and e.strerror else
               f"larger than the {_max_pixels()} pixels an image may be"
               if type(e).__name__ == "DecompressionBombError" else  # e.g. 30000²
               "not a file format imageio decodes, or a truncated or damaged one")
        raise InputError(f"cannot read as {_a(what)}: {why}", path, key=key) from None
    if img.dtype.kind not in "uifb" or img.size == 0 or not (
            img.ndim == 2 or (img.ndim == 3 and img.shape[-1] in (1, 2, 3, 4))):
        raise InputError(f"expected {_a(what)} (H, W) or (H, W, 1-4 channels), got an array of "
                         f"shape {img.shape} and type {img.dtype}", path, key=key)
    if img.dtype.kind in "ui":
        top = float(np.iinfo(img.dtype).max)
        img = img.astype(np.float64)
        img /= top  # in place: one float64 copy of the samples, not two
    else:
        img = np.asarray(img, np.float64)
        if not np.all(np.isfinite(img)):
            raise InputError(f"the {what} has non-finite values", path, key=key)
    return img[..., None] if img.ndim == 2 else img


def read_image(path, what: str = "image", key=None):
    """A PNG (or any image imageio reads) as display values in [0, 1]: `(rgb (H, W, 3),
    alpha (H, W) or None)`; grey is repeated to RGB; integer samples at the full scale of
    their type (a 16-bit file whose values all lie below 256 is still on the 65535 scale),
    floating-point samples as they are; CMYK, YCbCr, LAB and HSV images converted to RGB
    as Pillow converts them. `InputError` naming the file if it is not a regular, readable
    2-D image of finite values, or if reading it would not fit in memory (checked from its
    header, before decoding); `what` names the image in that message, `key` the scene key
    that gave the file (the editor marks that field)."""
    img = _decode(path, what, key)
    alpha = img[..., -1] if img.shape[-1] in (2, 4) else None
    grey_or_rgb = img[..., :3] if img.shape[-1] >= 3 else img[..., :1]
    return np.broadcast_to(grey_or_rgb, (*img.shape[:2], 3)).copy(), alpha


_SAID_COLOUR: set[str] = set()  # colour images read as grey, warned of once each


def read_grey(path, what: str = "greyscale image", key=None) -> np.ndarray:
    """A greyscale map `(H, W)` float64 in [0, 1] (a layer's thickness map, the melanin
    map): `read_image`'s values, colour averaged over R, G, B, alpha ignored, clipped to
    [0, 1]. Row 0 is the image's top. `InputError` naming the file as `read_image`."""
    img = _decode(path, what, key)  # not through read_image: no RGB copy of a grey map
    rgb = img[..., :3] if img.shape[-1] >= 3 else img[..., :1]
    if all(np.array_equal(rgb[..., c], rgb[..., 0]) for c in range(1, rgb.shape[-1])):
        grey = rgb[..., 0]  # grey as read, not (g + g + g) / 3 rounded
    else:  # said, not done in silence (a pure red map gives a third of its value)
        grey = rgb.mean(axis=-1)
        if str(path) not in _SAID_COLOUR:  # once a file: the checks and the render read it
            _SAID_COLOUR.add(str(path))
            warnings.warn(f"{path}: a colour image where a greyscale map is expected: read "
                          f"as the mean of R, G and B (mean {grey.mean():.3g} of 1); save it "
                          "as greyscale to say what you mean", stacklevel=2)
    return np.clip(grey, 0.0, 1.0)


def write_grey16(values, path) -> None:
    """A 16-bit grey PNG of `values (H, W)` in [0, 1] (clipped): a map a scene loads."""
    v = np.clip(np.asarray(values, np.float64), 0.0, 1.0)
    _write(path, png16_bytes(np.round(v * 65535).astype(np.uint16)))


def write_render(image, path, fmt: str) -> None:
    """A render in one of `FORMATS`: `png` 8-bit, `png16` 16-bit (display values, RGB or
    straight RGBA), `exr` linear premultiplied RGBA."""
    if fmt == "exr":
        if not exr_available():
            raise InputError("--format exr needs the OpenEXR bindings: pip install "
                             "'jaxskin[exr]'")
        write_exr(image, path)
    elif fmt == "png16":
        write_image(image, path, bits=16)
    else:
        write_image(image, path)


def write_height(h, path) -> None:
    """16-bit grey PNG: 0 = lowest (1 − depth), 65535 = the unwrinkled surface (1)."""
    h = np.clip(np.asarray(h, np.float64), 0.0, 1.0)
    _write(path, png_bytes(np.round(h * 65535).astype(np.uint16)))


def write_normals(n, mask, path) -> None:
    """8-bit RGB normal map, (n + 1)/2 per channel; off the mesh the flat (0, 0, 1)."""
    n = np.asarray(n, np.float64)
    n = np.where(np.asarray(mask)[..., None], n, [0.0, 0.0, 1.0])
    _write(path, png_bytes(np.round((n * 0.5 + 0.5) * 255).clip(0, 255).astype(np.uint8)))


def plot_flip(side: int, rotate=(0.0, 0.0, 0.0)) -> np.ndarray:
    """The field plot's axes: +z's side as the mesh is (x right, y up); the −z side
    ("planar-back") turned half round the axis the camera's turn `rotate` (degrees, as
    `camera.rotate`) turned it about, so that the plot shows it as the render does:
    x mirrored for a turn about y (the hand turned round), y for a turn about x (mirroring
    x there too would show the plot upside down against the render)."""
    if side > 0:
        return np.ones(3)
    from .view import rotation

    R = rotation(rotate)
    return np.array([-1.0, 1.0, -1.0]) if R[0, 0] <= R[1, 1] else np.array([1.0, -1.0, -1.0])


def write_field_plot(setup, path, title: str = "", rotate=(0.0, 0.0, 0.0)) -> None:
    """The mesh seen from +z (orthographic), d1 in red and d2 in green at the vertices that
    face the viewer, edited vertices in blue: the paper's "edit vectors" view (fig. 3.4).
    Seen from −z, where a planar texture belongs to that side ("planar-back": the camera
    sees the palm), turned as the camera's `rotate` turns it (`plot_flip`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    mesh = setup.mesh
    side = setup.tmap.side
    flip = plot_flip(side, rotate)
    v, f = mesh.vertices * flip, mesh.faces
    fn = mesh.face_normals() * flip
    front = fn[:, 2] > 0
    order = np.argsort(v[f].mean(axis=1)[:, 2])  # painter's order, back to front
    order = order[front[order]]
    fig, ax = plt.subplots(figsize=(7, 7), constrained_layout=True)
    shade = 0.55 + 0.45 * np.clip(fn[order, 2], 0, 1)
    ax.add_collection(PolyCollection(v[f[order]][..., :2], facecolors=np.repeat(
        shade[:, None], 3, axis=1), edgecolors=(0.6, 0.6, 0.6), linewidths=0.3))
    visible = side * mesh.normals[:, 2] > 0.2
    edges = v[f[:, [1, 2, 0]]] - v[f]
    scale = 1.2 * float(np.mean(np.linalg.norm(edges, axis=-1)))  # per unit of |d|
    for d, colour in ((setup.d1 * flip, "red"), (setup.d2 * flip, "green")):
        ax.quiver(v[visible, 0], v[visible, 1], d[visible, 0], d[visible, 1], color=colour,
                  angles="xy", scale_units="xy", scale=1 / scale, width=0.002, headwidth=3)
    edited = np.array([e.vertex for e in setup.edits], int)
    if edited.size:
        ax.plot(v[edited, 0], v[edited, 1], "o", color="blue", ms=5, label="edited vertices")
        ax.legend(loc="lower right", fontsize=8)
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_axis_off()
    ax.set_title(title or f"{mesh.name}: d1 (red), d2 (green)")
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=110)
    plt.close(fig)
