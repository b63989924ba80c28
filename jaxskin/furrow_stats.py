"""The character of a furrow pattern, measured: what the sequential and the lockstep furrow
programs (`wrinkles`, `lockstep`) must share though they differ texel by texel.

NumPy functions of a program's outputs (the height field before noise and its
`FurrowRecord` as `wrinkles.to_numpy_record` gives it), for tests and benchmarks:

- `coverage`: the share of mesh texels a furrow lowered;
- `orientation_histogram`: per pass, the structure-tensor orientation histogram of the
  texels its furrows drew (the owner image), weighted by line energy;
- `t_junctions`: per pass, the furrow ends that stopped on another furrow of the pass;
- `furrow_lengths`: per pass, each furrow's length (both halves), in texels;
- `compare`: all of them side by side for two programs, as the figures the tests bound.
"""

from __future__ import annotations

import numpy as np

from .wrinkles import END_FURROW

__all__ = ["compare", "coverage", "furrow_lengths", "histogram_distance", "ks_distance",
           "line_orientations", "orientation_histogram", "t_junctions"]


def coverage(h: np.ndarray, mask: np.ndarray, eps: float = 1e-4) -> float:
    """Share of the mesh's texels below the unwrinkled height 1 (by more than `eps`)."""
    mask = np.asarray(mask, bool)
    return float(np.mean(np.asarray(h)[mask] < 1.0 - eps))


def _box(a: np.ndarray, b: int) -> np.ndarray:
    """Mean over a b×b box (summed-area table), same shape as `a` (edge texels: partial)."""
    c = np.cumsum(np.cumsum(np.pad(a, ((b, 0), (b, 0))), 0), 1)
    return (c[b:, b:] - c[:-b, b:] - c[b:, :-b] + c[:-b, :-b]) / (b * b)


def line_orientations(h: np.ndarray, box: int = 7) -> tuple[np.ndarray, np.ndarray]:
    """Structure tensor: per texel, the orientation of the lines (degrees in [0, 180),
    counter-clockwise from +x on screen, y up) and a weight (energy × coherence). The
    image is smoothed first (the usual inner scale) or one-texel lines read as their
    pixel staircases."""
    gy, gx = np.gradient(_box(_box(np.asarray(h, np.float64), 3), 3))
    gy = -gy  # screen frame: y up
    jxx, jyy, jxy = _box(gx * gx, box), _box(gy * gy, box), _box(gx * gy, box)
    gradient_dir = 0.5 * np.degrees(np.arctan2(2 * jxy, jxx - jyy))
    return np.mod(gradient_dir + 90.0, 180.0), np.hypot(jxx - jyy, 2 * jxy)


def orientation_histogram(owner: np.ndarray, mask: np.ndarray, bins: int = 18) -> np.ndarray:
    """The orientation histogram (`bins` over 180°, summing to 1) of one pass's furrows,
    from its owner image (`>= 0` where a furrow of the pass drew), on the mesh."""
    angles, weights = line_orientations((np.asarray(owner) >= 0).astype(float), box=5)
    mask = np.asarray(mask, bool)
    hist, _ = np.histogram(angles[mask], bins=bins, range=(0, 180), weights=weights[mask])
    return hist / max(hist.sum(), 1e-300)


def histogram_distance(p: np.ndarray, q: np.ndarray) -> float:
    """Total variation distance of two normalised histograms: the share of weight that
    would have to move (0: equal, 1: disjoint)."""
    return float(0.5 * np.abs(np.asarray(p) - np.asarray(q)).sum())


def t_junctions(record: dict) -> int:
    """Furrow ends (halves) of one pass that stopped on another furrow: T-junctions."""
    return int(np.count_nonzero(np.asarray(record["reason"]) == END_FURROW))


def furrow_lengths(record: dict) -> np.ndarray:
    """Each recorded furrow's length in texels (its two halves)."""
    return np.asarray(record["length"]).sum(axis=1)


def ks_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Two-sample Kolmogorov–Smirnov statistic: the largest gap of the two empirical CDFs."""
    a, b = np.sort(np.asarray(a, float)), np.sort(np.asarray(b, float))
    grid = np.concatenate([a, b])
    return float(np.max(np.abs(np.searchsorted(a, grid, side="right") / len(a)
                               - np.searchsorted(b, grid, side="right") / len(b))))


def compare(mask, h_a, rec_a: dict, h_b, rec_b: dict) -> dict:
    """Program A (reference) against program B, both passes: `coverage` (a, b),
    `orientation` (per pass, the histogram distance), `t_junctions` (per pass, a, b, as a
    share of the pass's furrow halves), `lengths` (per pass: medians a, b; 90th percentiles
    a, b; the KS distance). Records must hold every furrow (`records` >= the count)."""
    out = {"coverage": (coverage(h_a, mask), coverage(h_b, mask)), "orientation": [],
           "t_junctions": [], "lengths": []}
    for p in range(2):
        ra, rb = rec_a[p], rec_b[p]
        out["orientation"].append(histogram_distance(
            orientation_histogram(ra["owner"], mask), orientation_histogram(rb["owner"], mask)))
        out["t_junctions"].append((t_junctions(ra) / max(ra["reason"].size, 1),
                                   t_junctions(rb) / max(rb["reason"].size, 1)))
        la, lb = furrow_lengths(ra), furrow_lengths(rb)
        out["lengths"].append((float(np.median(la)), float(np.median(lb)),
                               float(np.percentile(la, 90)), float(np.percentile(lb, 90)),
                               ks_distance(la, lb)))
    return out
