"""Meshes: load any OBJ/PLY/STL/GLB through trimesh, checked, with vertex normals and UVs.

Built-in names (`hand`, `hand_closed`, `foot`, `arm`, `face`) resolve to files in data/meshes.
A file that is not a triangle mesh, is empty, or has no usable faces is an `InputError`;
degenerate and duplicate faces are removed with a warning, never left to fail later; a mesh
whose triangles wind inward (its normals into the body) is turned outward with a warning.
"""

from __future__ import annotations

import dataclasses
import functools
import warnings
from pathlib import Path

import numpy as np

from .io import InputError, data_dir

__all__ = ["BUILTIN", "MAX_FACES", "Mesh", "default_projection", "load_mesh", "missing_uv",
           "signed_volume", "uv_parts", "vertex_normals"]

BUILTIN = {
    "hand": "hand_lowres.obj",
    "hand_closed": "hand_closed.obj",
    "foot": "foot.obj",
    "arm": "arm.obj",
    "face": "canonical_face_model.obj",
}

# The most triangles a scene's mesh may have. Measured (2-core CPU, `jaxskin render`,
# spectral skin with SSS, 512² image; `jaxskin.resources`): a 500k-face OBJ reads in 7 s
# and adds about 360 bytes a face to the peak; the texture-space rasterization costs what
# its texels cost, whatever the face count. The limit keeps a mistaken export (a 20M-face
# raw scan) from reading for minutes: decimate it first, keeping the UVs (Blender's
# Decimate, MeshLab's quadric edge collapse with texture). trimesh's
# `simplify_quadric_decimation` (fast-simplification) drops the UVs, so the loader does
# not decimate by itself.
MAX_FACES = 2_000_000


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
    """Load a built-in mesh by name, or any mesh file trimesh reads (OBJ with `vt`, PLY
    with per-vertex `s t`/`u v` or per-corner `texcoord`, GLB/glTF, STL, ...).

    A file is read once per process while it is unchanged (its path, size and time): a
    command loads its mesh several times (the scene's projection, the checks, the render),
    and a scan of 500k faces takes seconds to parse. The arrays are read-only.
    """
    key = str(name_or_path)
    path = data_dir() / "meshes" / BUILTIN[key] if key in BUILTIN else Path(key)
    if not path.exists():
        names = ", ".join(BUILTIN)
        raise InputError(f"no such mesh file (built-in meshes: {names})", path)
    if not path.is_file():  # a FIFO would block trimesh's read for ever
        what = "is a folder" if path.is_dir() else "not a regular file"
        raise InputError(f"{what}; expected a mesh file (OBJ, PLY, STL, GLB, ...)", path)
    st = path.stat()
    return _load(key, str(path.resolve()), st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=4)
def _load(key: str, resolved: str, mtime_ns: int, size: int) -> Mesh:
    """`load_mesh` of the file `resolved` as it is (`mtime_ns`, `size` key the cache)."""
    import trimesh

    path = data_dir() / "meshes" / BUILTIN[key] if key in BUILTIN else Path(key)
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
    if len(faces) > MAX_FACES:
        raise InputError(f"{len(faces):,} triangles; at most {MAX_FACES:,} are rendered: "
                         "decimate the scan first, keeping its UVs (Blender's Decimate "
                         "modifier, MeshLab's quadric edge collapse with texture)", path)
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
    # A UV seam splits a vertex into copies with the same position (trimesh makes one per
    # distinct (position, uv) pair): their normals are summed over every face at that
    # position, or each side of the seam would shade with half its faces (a crease).
    positions, weld = np.unique(vertices, axis=0, return_inverse=True)
    weld = weld.ravel()
    normals = vertex_normals(positions, weld[faces])[weld]
    uv = None
    visual_uv = getattr(getattr(loaded, "visual", None), "uv", None)
    if visual_uv is not None and len(visual_uv) == len(vertices):
        uv = np.asarray(visual_uv, np.float64)
        if not np.all(np.isfinite(uv)):
            raise InputError("texture coordinates (UVs) are not all finite", path)
    for array in (vertices, faces, normals, uv):
        if array is not None:
            array.flags.writeable = False
    return Mesh(key if key in BUILTIN else path.stem, vertices, faces, normals, uv)


def default_projection(name_or_path) -> str:
    """`mesh.projection` for a scene that does not set it: "uv" where the mesh has texture
    coordinates (a scan's own layout, the one its texture is painted on), else "planar".
    Every built-in scene sets its projection, so none changes with this."""
    return "uv" if load_mesh(name_or_path).uv is not None else "planar"


def missing_uv(name_or_path) -> str:
    """The one line that says a mesh has no texture coordinates, naming the file and, for a
    file of several parts, how many of them lack UVs."""
    key = str(name_or_path)
    if key in BUILTIN:
        return f"mesh '{key}' has no texture coordinates; use planar or cylindrical projection"
    path = Path(key)
    with_uv, parts = uv_parts(path)
    which = (f" ({parts - with_uv} of its {parts} parts have none, and the parts are "
             "merged)" if parts > 1 and with_uv else "")
    return (f"mesh {path} has no texture coordinates (UVs){which}; projection = \"uv\" "
            "needs them: export the mesh with UVs, or use planar or cylindrical projection")


def uv_parts(path) -> tuple[int, int]:
    """How many of a mesh file's parts (a glTF's primitives, an OBJ's objects) have
    texture coordinates, and how many parts there are: a scene of several parts loses its
    UVs when one part has none. `(0, 0)` where trimesh cannot read the file."""
    import trimesh

    try:
        loaded = trimesh.load(Path(path), process=False)
    except Exception:  # noqa: BLE001  (only to explain a missing UV; load_mesh says why)
        return 0, 0
    geometry = list(getattr(loaded, "geometry", {"": loaded}).values())
    with_uv = sum(getattr(getattr(g, "visual", None), "uv", None) is not None
                  for g in geometry)
    return with_uv, len(geometry)


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
