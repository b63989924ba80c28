"""Two direction fields on a mesh (Bando 2001 §3.1).

Initially d1 is (0, 1, 0) projected onto each vertex's tangent plane and d2 = d1 × n. The
user edits d1 and d2 (direction and magnitude, |d| in [0, 2]) at chosen vertices, each with
a weight λ (0 to 10); every other vertex takes eq. 3.1,

    d(v) = Σ wᵢ dᵢ / Σ wᵢ,   wᵢ = λᵢ / ‖p(v) − p(vᵢ)‖,

made tangent at v. Choices the paper leaves open, made here: an edit is first made tangent
at its own vertex, keeping its magnitude; the interpolated vector's direction is the
tangent part of the weighted mean and its magnitude the weighted mean of the edits'
magnitudes (so opposite edits do not cancel to zero); an edited vertex, or one at distance
0 from an edit, takes that edit exactly.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .mesh import Mesh

__all__ = ["Edit", "initial_fields", "interpolate_fields"]


@dataclasses.dataclass(frozen=True)
class Edit:
    """An edit at `vertex`: `d1`, `d2` (3-vectors, |d| <= 2) and weight `weight` (λ)."""

    vertex: int
    d1: tuple[float, float, float]
    d2: tuple[float, float, float]
    weight: float = 1.0


def _tangent(v, n):
    return v - np.sum(v * n, axis=-1, keepdims=True) * n


def initial_fields(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """d1 = (0, 1, 0) projected onto the tangent plane, d2 = d1 × n; both `(V, 3)`."""
    up = np.broadcast_to([0.0, 1.0, 0.0], mesh.normals.shape)
    d1 = _tangent(up, mesh.normals)
    return d1, np.cross(d1, mesh.normals)


def interpolate_fields(mesh: Mesh, edits: list[Edit]) -> tuple[np.ndarray, np.ndarray]:
    """The fields `(d1, d2)`, each `(V, 3)`, from `edits` by eq. 3.1 (initial if none)."""
    d1_init, d2_init = initial_fields(mesh)
    if not edits:
        return d1_init, d2_init
    idx = np.array([e.vertex for e in edits])
    lam = np.array([e.weight for e in edits], np.float64)
    n_e = mesh.normals[idx]
    dist = np.linalg.norm(mesh.vertices[:, None, :] - mesh.vertices[idx][None], axis=-1)
    at_edit = dist <= 0.0
    w = lam[None] / np.where(at_edit, 1.0, dist)
    out = []
    for which, init in ((0, d1_init), (1, d2_init)):
        raw = np.array([e.d1 if which == 0 else e.d2 for e in edits], np.float64)
        mag = np.linalg.norm(raw, axis=1)
        tangent = _tangent(raw, n_e)
        t_len = np.linalg.norm(tangent, axis=1, keepdims=True)
        d_edit = np.where(t_len > 0, tangent / np.maximum(t_len, 1e-300), 0.0) * mag[:, None]
        total = w.sum(axis=1, keepdims=True)
        safe_total = np.where(total > 0, total, 1.0)
        mean = (w @ d_edit) / safe_total
        magnitude = (w @ mag[:, None]) / safe_total
        direction = _tangent(mean, mesh.normals)
        length = np.linalg.norm(direction, axis=1, keepdims=True)
        fallback = init / np.maximum(np.linalg.norm(init, axis=1, keepdims=True), 1e-300)
        unit = np.where(length > 1e-9, direction / np.maximum(length, 1e-300), fallback)
        d = np.where(total > 0, unit * magnitude, init)
        # Exactly the edit at the edited vertex (and anywhere at distance 0 from it).
        hit = at_edit.any(axis=1)
        d[hit] = d_edit[np.argmax(at_edit[hit], axis=1)]
        out.append(d)
    return out[0], out[1]
