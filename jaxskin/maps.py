"""Writing texture-space maps: 16-bit height, normal map, and the field picture (fig. 3.4)."""

from __future__ import annotations

import numpy as np

from .io import atomic_write

__all__ = ["png_bytes", "write_field_plot", "write_height", "write_image", "write_normals"]


def png_bytes(image: np.ndarray) -> bytes:
    import imageio.v3 as iio

    return iio.imwrite("<bytes>", image, extension=".png")


def _write(path, data: bytes) -> None:
    with atomic_write(path, "wb") as fh:
        fh.write(data)


def write_image(image, path) -> None:
    """An 8-bit RGB PNG of display values in [0, 1] (clipped)."""
    image = np.clip(np.asarray(image, np.float64), 0.0, 1.0)
    _write(path, png_bytes(np.round(image * 255).astype(np.uint8)))


def write_height(h, path) -> None:
    """16-bit grey PNG: 0 = lowest (1 − depth), 65535 = the unwrinkled surface (1)."""
    h = np.clip(np.asarray(h, np.float64), 0.0, 1.0)
    _write(path, png_bytes(np.round(h * 65535).astype(np.uint16)))


def write_normals(n, mask, path) -> None:
    """8-bit RGB normal map, (n + 1)/2 per channel; off the mesh the flat (0, 0, 1)."""
    n = np.asarray(n, np.float64)
    n = np.where(np.asarray(mask)[..., None], n, [0.0, 0.0, 1.0])
    _write(path, png_bytes(np.round((n * 0.5 + 0.5) * 255).clip(0, 255).astype(np.uint8)))


def write_field_plot(setup, path, title: str = "") -> None:
    """The mesh seen from +z (orthographic), d1 in red and d2 in green at the vertices that
    face the viewer, edited vertices in blue: the paper's "edit vectors" view (fig. 3.4)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    mesh = setup.mesh
    v, f = mesh.vertices, mesh.faces
    fn = mesh.face_normals()
    front = fn[:, 2] > 0
    order = np.argsort(v[f].mean(axis=1)[:, 2])  # painter's order, back to front
    order = order[front[order]]
    fig, ax = plt.subplots(figsize=(7, 7), constrained_layout=True)
    shade = 0.55 + 0.45 * np.clip(fn[order, 2], 0, 1)
    ax.add_collection(PolyCollection(v[f[order]][..., :2], facecolors=np.repeat(
        shade[:, None], 3, axis=1), edgecolors=(0.6, 0.6, 0.6), linewidths=0.3))
    visible = mesh.normals[:, 2] > 0.2
    edges = v[f[:, [1, 2, 0]]] - v[f]
    scale = 1.2 * float(np.mean(np.linalg.norm(edges, axis=-1)))  # per unit of |d|
    for d, colour in ((setup.d1, "red"), (setup.d2, "green")):
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
