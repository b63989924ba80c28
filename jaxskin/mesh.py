"""Meshes: load any OBJ/PLY/STL/GLB through trimesh, checked, with vertex normals and UVs.

Built-in names (`hand`, `hand_closed`, `foot`, `arm`, `face`) resolve to files in data/meshes.
A file that is not a triangle mesh, is empty, or has no usable faces is an `InputError`;
degenerate and duplicate faces are removed with a warning, never left to fail later; a mesh
whose triangles wind inward (its normals into the body) is turned outward with a warning.
"""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import numpy as np

from .io import InputError, data_dir

__all__ = ["BUILTIN", "Mesh", "load_mesh", "signed_volume", "vertex_normals"]

BUILTIN = {
    "hand": "hand_lowres.obj",
    "hand_closed": "hand_closed.obj",
    "foot": "foot.obj",
    "arm": "arm.obj",
    "face": "canonical_face_model.obj",
}


@dataclasses.dataclass(frozen=True, eq=False)
class Mesh:
    """`vertices (V, 3)`, `faces (F, 3)`, unit `normals (V, 3)`, `uv (V, 2)` or None (host
    arrays, float64), and the `name` it was loaded by."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    uv: np.ndarray | None

    def face_normals(self) -> np.ndarray:
        """Unit normals of the faces `(F, 3)`, by the right-hand rule of their vertex order."""
        a, b, c = (self.vertices[self.faces[:, i]] for i in range(3))
        n = np.cross(b - a, c - a)
        return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


def load_mesh(name_or_path) -> Mesh:
    """Load a built-in mesh by name, or any mesh file trimesh reads."""
    import trimesh

    key = str(name_or_path)
    path = data_dir() / "meshes" / BUILTIN[key] if key in BUILTIN else Path(key)
    if not path.exists():
        names = ", ".join(BUILTIN)
        raise InputError(f"no such mesh file (built-in meshes: {names})", path)
    try:
        loaded = trimesh.load(path, process=False, force="mesh")
    except Exception as e:  # noqa: BLE001  (trimesh raises many kinds; all mean "unreadable")
        # An ImportError is trimesh reaching for an optional decoder of text in an unknown
        # encoding: for the user, a file that is not a mesh.
        why = ("not text in a known encoding" if isinstance(e, ImportError) else
               f"{e.__class__.__name__}: {e}")
        raise InputError(f"cannot read as a mesh ({why})", path) from None
    vertices = np.asarray(getattr(loaded, "vertices", np.empty((0, 3))), np.float64)
    faces = np.asarray(getattr(loaded, "faces", np.empty((0, 3))), np.int64)
    if len(vertices) == 0 or len(faces) == 0:
        raise InputError("the mesh is empty (no vertices or no triangles); expected a "
                         "triangle mesh", path)
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise InputError(f"faces have {faces.shape[-1]} corners; expected triangles", path)
    if not np.all(np.isfinite(vertices)):
        raise InputError("vertex coordinates are not all finite", path)
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    area2 = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    scale = np.ptp(vertices, axis=0).max()
    degenerate = (area2 <= 1e-12 * scale * scale) | (faces[:, 0] == faces[:, 1]) | (
        faces[:, 1] == faces[:, 2]) | (faces[:, 0] == faces[:, 2])
    _, first = np.unique(np.sort(faces, axis=1), axis=0, return_index=True)
    duplicate = np.ones(len(faces), bool)
    duplicate[first] = False
    drop = degenerate | duplicate
    if drop.all():
        raise InputError("every triangle is degenerate (zero area)", path)
    if drop.any():
        _warn_once(path, f"{path}: removed {int(degenerate.sum())} degenerate and "
                         f"{int((duplicate & ~degenerate).sum())} duplicate triangles")
        faces = faces[~drop]
    if signed_volume(vertices, faces) < -INWARD:
        _warn_once(path, f"{path}: the triangles wind inward (clockwise seen from outside: "
                         "normals into the body, which would render flat and dark); "
                         "reversed for the render")
        faces = faces[:, ::-1].copy()
    normals = vertex_normals(vertices, faces)
    uv = None
    visual_uv = getattr(getattr(loaded, "visual", None), "uv", None)
    if visual_uv is not None and len(visual_uv) == len(vertices):
        uv = np.asarray(visual_uv, np.float64)
    return Mesh(key if key in BUILTIN else path.stem, vertices, faces, normals, uv)


# A mesh whose signed volume about its centroid is below −INWARD × its bounding box's
# volume winds inward. Measured: the built-in meshes (open at the wrist, the cuts, the
# face's shell) +0.12 to +0.35, a capsule +0.72, an open tube +0.52; reversed, the same
# negated; a flat patch about 0, left as it is.
INWARD = 0.05


def signed_volume(vertices, faces) -> float:
    """The volume the triangles enclose about the vertices' centroid, by the right-hand
    rule of their vertex order, as a fraction of the bounding box's volume (its extent in
    the flattest direction floored at a thousandth of the largest): > 0 for outward
    normals, < 0 inward, near 0 for an open patch."""
    o = vertices.mean(axis=0)
    a, b, c = (vertices[faces[:, i]] - o for i in range(3))
    volume = float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum()) / 6.0
    extent = np.ptp(vertices, axis=0)
    box = float(np.prod(np.maximum(extent, 1e-3 * extent.max())))
    return volume / box if box > 0 else 0.0


_WARNED: set = set()


def _warn_once(path, message: str) -> None:
    """A warning about a mesh file, once per process for the file as it is (a command loads
    a mesh more than once: checks, then the work)."""
    try:
        st = Path(path).stat()
        key = (str(Path(path).resolve()), st.st_mtime_ns, st.st_size, message)
    except OSError:
        key = (str(path), message)
    if key not in _WARNED:
        _WARNED.add(key)
        warnings.warn(message, stacklevel=3)


def vertex_normals(vertices, faces):
    """Area-weighted vertex normals; a vertex on no face gets +z.

    **Arguments:**

    - `vertices (V, 3)` float: the vertex positions.
    - `faces (F, 3)` int: the triangles (their winding picks the normals' side).

    **Returns:** `(V, 3)` unit normals, each the normalised sum of its faces' cross
    products (so weighted by their areas)."""
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    n = np.cross(b - a, c - a)
    out = np.zeros_like(vertices)
    for i in range(3):
        np.add.at(out, faces[:, i], n)
    length = np.linalg.norm(out, axis=1, keepdims=True)
    return np.where(length > 0, out / np.maximum(length, 1e-300), [0.0, 0.0, 1.0])
