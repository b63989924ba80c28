"""The session's view tools: a vertex picked, the direction fields' arrows, brush strokes.

A stroke paints a cosmetic layer's thickness map (16-bit, texture space) with the soft
brush of `_brush`.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .. import render, texture
from ..scene import SceneConfig
from . import _brush as brush
from ._document import EditorError

__all__ = ["Painting", "Stroke"]


@dataclasses.dataclass
class Stroke:
    """A brush stroke in progress: its layer, the map before it and the union of its dabs."""

    id: str
    layer: str
    before: np.ndarray  # float64 (H, W) in [0, 1]
    mask: np.ndarray  # float64 (H, W) in [0, 1]
    last: tuple | None = None  # the stroke's last point so far (image pixels)



class Painting:
    """The `Session`'s view tools (its `pick`, `fields` and `paint_stroke`)."""

    def _view(self):
        config = self.scene.config
        return config, render.prepare(self._prepared_config(config)).view

    def _sample(self, view, k: int, x, y):
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                   and math.isfinite(v) for v in (x, y)):
            raise EditorError("expected pixel coordinates x, y (numbers)", 400)
        H, W = view.mask.shape
        if not (0 <= y * k < H and 0 <= x * k < W):  # before floor: 1e308 * k is inf
            raise EditorError(f"pixel ({x}, {y}) is outside the {W // k}x{H // k} image", 400)
        return int(math.floor(y * k)), int(math.floor(x * k))

    def pick(self, x, y) -> dict:
        """The mesh vertex nearest to image pixel `(x, y)` (the triangle the view's raster
        sees there, its corner of largest barycentric), with the screen's axes in the
        mesh's frame (for turning a drag into a direction)."""
        config, view = self._view()
        k = config.supersample
        i, j = self._sample(view, k, x, y)
        tri = int(view.raster.tri[i, j])
        R = view.R
        axes = {"right": (R.T @ [1.0, 0.0, 0.0]).tolist(),
                "down": (R.T @ [0.0, -1.0, 0.0]).tolist()}
        if tri < 0:
            return {"hit": False, **axes}
        mesh = texture.setup(config.texture).mesh
        vertex = int(mesh.faces[tri][int(np.argmax(view.raster.bary[i, j]))])
        s = texture.setup(config.texture)
        return {"hit": True, "vertex": vertex, "position": mesh.vertices[vertex].tolist(),
                "d1": s.d1[vertex].tolist(), "d2": s.d2[vertex].tolist(),
                "normal": mesh.normals[vertex].tolist(),
                "screen": (view.xy[vertex] / k).tolist(), **axes}

    def fields(self, step: int = 24) -> dict:
        """The direction fields seen in the view, for the arrows: every `step` image pixels
        on the mesh, `[x, y, d1x, d1y, d2x, d2y]` (screen directions, image pixels per unit
        of |d|), and each edit's vertex on the screen."""
        config, view = self._view()
        k = config.supersample
        s = texture.setup(config.texture)
        H, W = view.mask.shape
        ys = (np.arange(step // 2, H // k, step) * k + k // 2)
        xs = (np.arange(step // 2, W // k, step) * k + k // 2)
        ii, jj = np.meshgrid(ys, xs, indexing="ij")
        tri = view.raster.tri[ii, jj]
        on = tri >= 0
        ii, jj, tri = ii[on], jj[on], tri[on]
        bary = view.raster.bary[ii, jj].astype(np.float64)
        corners = s.mesh.faces[tri]
        out = [(ii + 0.5) / k, (jj + 0.5) / k]
        for d in (s.d1, s.d2):
            v = np.einsum("nk,nkc->nc", bary, d[corners]) @ view.R.T
            out += [v[:, 0], -v[:, 1]]
        rows = np.stack([out[1], out[0], *out[2:]], axis=1)
        edits = [{"index": n, "vertex": e.vertex, "screen": (view.xy[e.vertex] / k).tolist()}
                 for n, e in enumerate(s.edits)]
        return {"arrows": np.round(rows, 2).tolist(), "edits": edits}

    def paint_stroke(self, stroke: str, layer: str, points, radius: float, strength: float,
                     erase: bool = False) -> dict:
        """Paint (or erase) `layer`'s thickness map along `points` (image pixels), a soft
        brush of `radius` image pixels: each point's texel from the view's texture lookup,
        the radius in texels from the lookup's local scale. Repeated calls with the same
        `stroke` id extend one stroke (one undo step; dabs do not pile up within it).
        Returns `{"dabs": n, "radius_px": r}`: r is the last dab's radius in image pixels
        (None if no dab landed on the mesh), above `radius` where the texels are larger
        than the brush (a close view of a coarse texture), so the page can draw the brush
        circle as large as what it paints."""
        config, view = self._view()
        if config.spectral is None or layer not in [s.name for s in config.spectral.layers]:
            names = [s.name for s in config.spectral.layers] if config.spectral else []
            none = "none; material.model must be spectral or biophysical"
            raise EditorError(f"no cosmetic layer {layer!r} to paint (this scene's layers: "
                              f"{', '.join(names) or none})", 400, "layer")
        if not (isinstance(points, list) and 0 < len(points) <= 10000 and all(
                isinstance(p, list) and len(p) == 2 and all(
                    isinstance(c, (int, float)) and not isinstance(c, bool)
                    and math.isfinite(c) for c in p) for p in points)):
            raise EditorError("points: expected a list of [x, y] pixel positions (1-10000)", 400)
        for name, v, lo, hi in (("radius", radius, 0.5, 500.0), ("strength", strength, 0, 1)):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not lo <= v <= hi:
                raise EditorError(f"{name}: expected a number in [{lo:g}, {hi:g}], got {v!r}")
        H, W = (n // config.supersample for n in view.mask.shape)
        far = [p for p in points if not (-W <= p[0] <= 2 * W and -H <= p[1] <= 2 * H)]
        if far:  # a drag may leave the image, not by more than its size
            raise EditorError(f"points: {far[0]} is far outside the {W}x{H} image (at most "
                              "one image size beyond its edges)", 400)
        k = config.supersample
        s = texture.setup(config.texture)
        Ht, Wt = s.tmap.height, s.tmap.width
        if self._stroke is None or self._stroke.id != stroke or self._stroke.layer != layer:
            before = self._layer_map(config, layer)
            self._record()
            self._stroke = Stroke(str(stroke), layer, before, np.zeros((Ht, Wt)))
        mask = self._stroke.mask
        points = [tuple(map(float, p)) for p in points]
        last = self._stroke.last  # the stroke goes on from where its last request ended
        dabs = brush.dabs(points, radius) if last is None else brush.dabs(
            [last, *points], radius)[1:]
        self._stroke.last = points[-1]
        H, W = view.mask.shape
        shaded = view.shaded  # a property over the whole view: once, not per dab
        shown = None
        rows = [Ht, 0]  # the texel rows this request's dabs reach
        for x, y in dabs:
            i, j = math.floor(y * k), math.floor(x * k)
            if not (0 <= i < H and 0 <= j < W and shaded[i, j]):
                continue  # off the image (a drag that left the view: the page captures the
                # pointer) or off the mesh; a stroke may go out and come back
            t = view.tex[i, j].astype(np.float64)
            scale = brush.texels_per_pixel(view, i, j, k, shaded)
            r = max(radius * scale, brush.MIN_RADIUS)
            brush.dab(mask, t[0], t[1], r, s.tmap.wrap_x)
            rows = [min(rows[0], max(int(t[1] - r - 1), 0)),
                    max(rows[1], min(int(t[1] + r + 1) + 1, Ht))]
            shown = r / scale
        target = 0.0 if erase else 1.0
        before = self._stroke.before
        first = layer not in self.paint

        def painted(a, b):  # the map's rows a:b as the stroke leaves them
            value = before[a:b] + (target - before[a:b]) * float(strength) * mask[a:b]
            return np.round(np.clip(value, 0, 1) * 65535).astype(np.uint16)

        if first:
            new = painted(0, Ht)
        else:  # elsewhere the map is as the last request left it (the same values)
            new = self.paint[layer].copy()
            if rows[0] < rows[1]:
                new[rows[0]:rows[1]] = painted(*rows)
        self.paint = {**self.paint, layer: new}
        if first:  # the layer's regions or image give way to its map
            self.scene = self._build(self.changes, self.paint)
        self.version += 1
        return {"dabs": len(dabs), "radius_px": shown}

    def _layer_map(self, config: SceneConfig, layer: str) -> np.ndarray:
        """A layer's thickness map `(H, W)` in [0, 1] as the render has it now."""
        if layer in self.paint:
            return self.paint[layer].astype(np.float64) / 65535.0
        arrays = self.arrays(config)
        names = [s.name for s in config.spectral.layers]
        s = texture.setup(config.texture)
        out = np.zeros(s.tmap.height * s.tmap.width)
        out[np.asarray(arrays["texels"])] = np.asarray(arrays["cover"][names.index(layer)])
        return out.reshape(s.tmap.height, s.tmap.width)
