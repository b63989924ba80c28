"""The editor's soft brush: a stroke of image pixels as dabs in texture space.

A stroke's points (image pixels) are filled in to a third of the radius apart; each dab
lands on the texel the view sees there (`View.tex`, the rasterizer's texture lookup) with a
radius scaled by how many texels one image pixel spans there, so a brush of a given size on
the screen paints that size on the skin wherever the texture is stretched.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["MIN_RADIUS", "dab", "dabs", "texels_per_pixel"]

MIN_RADIUS = 0.75  # texels: a smaller dab could fall between texel centres and paint nothing


MAX_DABS = 20000  # per request: else a segment of 1e300 pixels makes a list as long


def dabs(points: list, radius: float) -> list:
    """The stroke's dab centres: its points, with more between any two further apart than
    a third of the radius (a continuous line at any drag speed)."""
    out = [points[0]]
    spacing = max(radius / 3.0, 0.5)
    for (x0, y0), (x1, y1) in zip(points, points[1:], strict=False):
        n = min(int(math.ceil(math.hypot(x1 - x0, y1 - y0) / spacing)), MAX_DABS)
        out += [(x0 + (x1 - x0) * t / n, y0 + (y1 - y0) * t / n) for t in range(1, n + 1)]
    return out[:MAX_DABS]


def texels_per_pixel(view, i: int, j: int, k: int, shaded=None) -> float:
    """How many texels one image pixel spans at view sample `(i, j)` (from neighbours on
    the same surface; 1 where none is). `shaded`: `view.shaded` (a property computed
    over the whole view at each use: a stroke's caller passes it once)."""
    H, W = view.mask.shape
    shaded = view.shaded if shaded is None else shaded
    steps = []
    for di, dj in ((0, 1), (1, 0), (0, -1), (-1, 0)):
        a, b = i + di, j + dj
        if 0 <= a < H and 0 <= b < W and shaded[a, b]:
            d = np.abs(view.tex[a, b] - view.tex[i, j])
            if d.max() < 8:  # not across a seam or a fold
                steps.append(float(np.hypot(*d)))
    return k * float(np.median(steps)) if steps else 1.0


def dab(mask: np.ndarray, cx: float, cy: float, r: float, wrap: bool) -> None:
    """The union (max) of `mask` and a soft round dab at texel coordinates `(cx, cy)`,
    radius `r` texels (at least `MIN_RADIUS`): (1 − (d/r)²)² inside, 0 outside."""
    H, W = mask.shape
    r = max(r, MIN_RADIUS)
    y0, y1 = max(int(cy - r - 1), 0), min(int(cy + r + 1) + 1, H)
    x0, x1 = int(cx - r - 1), int(cx + r + 1) + 1
    if not wrap:
        x0, x1 = max(x0, 0), min(x1, W)
    if y1 <= y0 or x1 <= x0:
        return
    yy, xx = np.mgrid[y0:y1, x0:x1]
    d2 = ((xx + 0.5 - cx) ** 2 + (yy + 0.5 - cy) ** 2) / (r * r)
    f = np.where(d2 < 1, (1 - d2) ** 2, 0.0)
    cols = np.mod(xx, W) if wrap else xx
    np.maximum.at(mask, (yy, cols), f)
