"""Mapping a mesh and its direction fields to texture space (Bando 2001 §3.2).

- planar: (x, y, z) → (x, y); vectors keep (dx, dy). Where both sides of a part project
  onto the same texels (the palm under the back of the hand), the side facing the camera
  owns them: +z, or −z ("planar-back", which a scene picks when its camera is turned to
  see that side: `scene.planar_side`).
- cylindrical (eq. 3.2): about the y axis, s = angle from +z (0 to 2π), t = y; a vector is
  rotated by −s about y and keeps (dx', dy'). Texels are square at the mean radius, so a
  long part gets a texture taller than wide. The seam at s = 0 wraps.
- uv: the mesh's own texture coordinates (beyond the paper: the face); vectors through the
  per-vertex map from the tangent plane to uv, keeping their magnitude.

Pixel coordinates put x to the right and y down (row 0 at the top = largest t). Texture
vectors are in the paper's abstract units (|d| in [0, 2]), in that pixel frame.

For bump mapping (`jaxskin.bump`) each map also gives the surface gradients of its texture
coordinates, ∇s and ∇t (t up), in texels per nominal texel (`TextureMap.texel`, the map's
texel size on the surface): about unit vectors along the texture axes where the map is not
stretched. Planar: (1, 0, 0) and (0, 1, 0). Cylindrical: the 3D gradients of eq. 3.2,
(r̄/r)(cos s, 0, −sin s) and (0, 1, 0). uv: per triangle from its positions and texture
coordinates (rows of the map M with M [e1 e2] = [f1 f2]), area-averaged at the vertices.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import warnings

import numpy as np

from .mesh import Mesh
from .raster import Raster, rasterize, unwrap_seam

__all__ = ["KINDS", "TextureMap", "cylinder_to_xyz", "project"]

KINDS = ("planar", "cylindrical", "uv")
MARGIN = 0.04  # of the texture, around planar and cylindrical maps


@dataclasses.dataclass(frozen=True, eq=False)
class TextureMap:
    """A mesh in texture space: vertex `xy (V, 2)` in pixels, the rasterizer's `depth`, and
    the map of tangent vectors `vector_map (V, 2, 3)` (texture vector = M @ d)."""

    kind: str
    mesh: Mesh
    width: int
    height: int
    xy: np.ndarray
    depth: np.ndarray | None
    wrap_x: bool
    vector_map: np.ndarray
    keep_magnitude: bool = False
    texel: float = 1.0  # the nominal texel size on the surface, mesh units
    jacobian: np.ndarray | None = None  # (V, 2, 3) ∂(pixel x, y)/∂P; None: vector_map
    # With `wrap_x`, the faces that straddle the cut `(F,)` (a UV map's seam faces); None:
    # every face wider than half the texture (the cylindrical projection's rule).
    seam: np.ndarray | None = None
    # Planar: the side whose faces own the texels both sides project to, +1 (facing +z) or
    # −1 (facing −z: "planar-back", for a camera that sees that side).
    side: int = 1

    def gradients(self) -> np.ndarray:
        """Per vertex `(V, 2, 3)`: the surface gradients ∇s, ∇t of the texture coordinates
        (t up), in texels per `texel` (dimensionless; unit length where undistorted)."""
        J = self.vector_map if self.jacobian is None else self.jacobian
        return J * np.array([1.0, -1.0])[None, :, None] * self.texel

    @functools.cached_property
    def raster(self) -> Raster:
        """The texture's `Raster` (triangle and barycentrics per texel), made once."""
        return rasterize(self.xy, self.mesh.faces, self.height, self.width, self.depth,
                         self.wrap_x, self.seam)

    def vectors(self, d: np.ndarray) -> np.ndarray:
        """Texture-space vectors `(V, 2)` of tangent vectors `d (V, 3)`."""
        v = np.einsum("vij,vj->vi", self.vector_map, d)
        if self.keep_magnitude:
            length = np.linalg.norm(v, axis=1, keepdims=True)
            v = np.where(length > 0, v / np.maximum(length, 1e-300), 0.0) * np.linalg.norm(
                d, axis=1, keepdims=True)
        return v

    def face_corners(self) -> np.ndarray:
        """Triangle corners `(F, 3, 2)` in pixels, unwrapped across a cylinder's seam (x may
        exceed the width there; texture lookups wrap)."""
        corners = self.xy[self.mesh.faces]
        return unwrap_seam(corners, self.width, self.seam) if self.wrap_x else corners

    def texel_size(self) -> float:
        """The mean size of a texel on the surface, in mesh units: sqrt(surface area /
        texture area), both summed over the triangles (so weighted by area)."""
        f = self.mesh.faces
        e = self.mesh.vertices[f[:, 1:]] - self.mesh.vertices[f[:, :1]]
        surface = 0.5 * np.linalg.norm(np.cross(e[:, 0], e[:, 1]), axis=1).sum()
        c = self.face_corners()
        d = c[:, 1:] - c[:, :1]
        texels = 0.5 * np.abs(d[:, 0, 0] * d[:, 1, 1] - d[:, 0, 1] * d[:, 1, 0]).sum()
        return math.sqrt(surface / max(texels, 1e-300))

    def centroids(self) -> np.ndarray:
        """Triangle centroids `(F, 2)` in pixels (wrapped back into a cylinder's texture)."""
        c = self.face_corners().mean(axis=1)
        if self.wrap_x:
            c[:, 0] %= self.width
        return c


def project(kind: str, mesh: Mesh, size: int) -> TextureMap:
    """Map `mesh` to a texture `size` texels wide by `kind` ('planar', 'cylindrical', 'uv';
    'planar-back': planar, the side facing −z owning the shared texels)."""
    if kind in ("planar", "planar-back"):
        return _planar(mesh, size, -1 if kind == "planar-back" else 1)
    if kind == "cylindrical":
        return _cylindrical(mesh, size)
    if kind == "uv":
        return _uv(mesh, size)
    raise ValueError(f"projection must be one of {KINDS}, got {kind!r}")


def _planar(mesh: Mesh, size: int, side: int = 1) -> TextureMap:
    p = mesh.vertices
    lo, hi = p[:, :2].min(axis=0), p[:, :2].max(axis=0)
    scale = size * (1 - 2 * MARGIN) / max(float(np.max(hi - lo)), 1e-300)
    centre = (lo + hi) / 2
    xy = np.stack([(p[:, 0] - centre[0]) * scale + size / 2,
                   size / 2 - (p[:, 1] - centre[1]) * scale], axis=1)
    M = np.broadcast_to(np.array([[1.0, 0, 0], [0, -1.0, 0]]), (len(p), 2, 3))
    # The rasterizer keeps the least depth: the side facing `side` · z wins shared texels.
    return TextureMap("planar", mesh, size, size, xy, -side * p[:, 2], False, np.array(M),
                      texel=1.0 / scale, jacobian=np.array(M) * scale, side=side)


def _cylindrical(mesh: Mesh, size: int) -> TextureMap:
    p = mesh.vertices
    r = np.hypot(p[:, 0], p[:, 2])
    s = np.mod(np.arctan2(p[:, 0], p[:, 2]), 2 * math.pi)  # eq. 3.2: arccos(z/r), 2π − … if x <= 0
    texel = 2 * math.pi * float(np.mean(r)) / size  # square texels at the mean radius
    t_lo, t_hi = p[:, 1].min(), p[:, 1].max()
    height = int(math.ceil((t_hi - t_lo) / texel / (1 - 2 * MARGIN)))
    xy = np.stack([s / (2 * math.pi) * size,
                   height / 2 - (p[:, 1] - (t_lo + t_hi) / 2) / texel], axis=1)
    c, n = np.cos(s), np.sin(s)
    # Rotate by −s about y, keep (x', y') with y down: x' = cos s dx − sin s dz.
    M = np.zeros((len(p), 2, 3))
    M[:, 0, 0], M[:, 0, 2], M[:, 1, 1] = c, -n, -1.0
    # ∂(pixel)/∂P: ∇s = e_s / r (per radian, size / 2π pixels each), ∇y = e_y / texel.
    J = M * np.stack([size / (2 * math.pi) / np.maximum(r, 1e-12 * texel),
                      np.full_like(r, 1.0 / texel)], axis=1)[:, :, None]
    return TextureMap("cylindrical", mesh, size, height, xy, -r, True, M, texel=texel,
                      jacobian=J)


def cylinder_to_xyz(s, t, r):
    """The inverse of the cylindrical projection: a point from (s, t) and its radius r."""
    return np.stack([r * np.sin(s), t, r * np.cos(s)], axis=-1)


def _seams(mesh: Mesh, corners: np.ndarray, size: int) -> np.ndarray:
    """Per face and UV axis (F, 2): whether the triangle is a seam with shared vertices.

    It spans more than half the texture along that axis, and drawn the short way round
    (`unwrap_seam`) its texels per unit of its longest edge come nearer the mesh's median
    than they are: an N-sided tube's seam face spans (N-1)/N of the texture and 1/N once
    unwrapped, as its neighbours do; a square mapped onto the whole texture by two triangles
    spans it all as every face does, and unwrapped collapses."""
    p = mesh.vertices[mesh.faces]  # (F, 3, 3)
    edge = np.maximum(np.linalg.norm(p - np.roll(p, 1, axis=1), axis=2).max(axis=1), 1e-300)
    seam = np.zeros((len(corners), 2), bool)
    for axis in (0, 1):
        c = corners[..., [axis, 1 - axis]]  # the axis first, as unwrap_seam reads x
        span = np.ptp(c[..., 0], axis=1)
        short = np.ptp(unwrap_seam(c, size)[..., 0], axis=1)
        typical = np.median(span / edge)
        with np.errstate(divide="ignore"):
            before = np.abs(np.log(span / edge / typical))
            after = np.abs(np.log(short / edge / typical))
        seam[:, axis] = (span > size / 2) & (after < before)
    return seam


def _pinv_3x2(E: np.ndarray) -> np.ndarray:
    """The pseudo-inverses `(F, 2, 3)` of the face edge matrices `E (F, 3, 2)`: (EᵀE)⁻¹Eᵀ
    in closed form where the edges span a plane (numpy's SVD per face took 7 s for 500k
    faces), `np.linalg.pinv` for the few that do not."""
    G = np.einsum("fki,fkj->fij", E, E)
    det = G[:, 0, 0] * G[:, 1, 1] - G[:, 0, 1] * G[:, 1, 0]
    scale = np.maximum(G[:, 0, 0] * G[:, 1, 1], 1e-300)
    good = det > 1e-12 * scale
    inv = np.stack([np.stack([G[:, 1, 1], -G[:, 0, 1]], -1),
                    np.stack([-G[:, 1, 0], G[:, 0, 0]], -1)], 1) / np.where(good, det, 1.0)[
        :, None, None]
    out = inv @ E.transpose(0, 2, 1)
    if not good.all():
        out[~good] = np.linalg.pinv(E[~good])
    return out


def _uv(mesh: Mesh, size: int) -> TextureMap:
    if mesh.uv is None:
        raise ValueError(f"mesh '{mesh.name}' has no texture coordinates; use planar or "
                         "cylindrical projection")
    xy = np.stack([mesh.uv[:, 0] * size, (1 - mesh.uv[:, 1]) * size], axis=1)
    f = mesh.faces
    corners = xy[f]  # (F, 3, 2)
    seam = _seams(mesh, corners, size)  # (F, 2)
    # A triangle across more than half the texture, stretched far beyond the mesh's usual
    # texels per unit length, is a seam whose vertices are shared (u running 0 → 1 round a
    # cylinder and back to 0): drawn as it is, it smears across every row of the texture.
    # Across u it is read as a wrap (the cylindrical projection's rule: the texture wraps
    # in u); across v nothing can be done but say so.
    if seam[:, 0].any():
        warnings.warn(f"mesh '{mesh.name}': {int(seam[:, 0].sum())} triangles span more "
                      "than half the texture in u: read as a seam where u wraps from 1 back "
                      "to 0 (the texture wraps in u)", stacklevel=3)
        corners = unwrap_seam(corners, size, seam[:, 0])
    if seam[:, 1].any():
        warnings.warn(f"mesh '{mesh.name}': {int(seam[:, 1].sum())} triangles span more "
                      "than half the texture in v (a seam with shared vertices?): they "
                      "smear across the texture; split the seam's vertices", stacklevel=3)
    wrap = bool(seam[:, 0].any())
    # Per face, the linear map M from the face plane to pixels: M [e1 e2] = [f1 f2].
    E = np.stack([mesh.vertices[f[:, 1]] - mesh.vertices[f[:, 0]],
                  mesh.vertices[f[:, 2]] - mesh.vertices[f[:, 0]]], axis=2)  # (F, 3, 2)
    Fp = np.stack([corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]],
                  axis=2)  # (F, 2, 2)
    M_face = Fp @ _pinv_3x2(E)  # (F, 2, 3)
    area = 0.5 * np.linalg.norm(np.cross(E[..., 0], E[..., 1]), axis=1)
    M = np.zeros((len(xy), 2, 3))
    weight = np.zeros(len(xy))
    for i in range(3):
        np.add.at(M, f[:, i], M_face * area[:, None, None])
        np.add.at(weight, f[:, i], area)
    M /= np.maximum(weight, 1e-300)[:, None, None]
    tmap = TextureMap("uv", mesh, size, size, xy, None, wrap, M, keep_magnitude=True,
                      seam=seam[:, 0] if wrap else None)
    return dataclasses.replace(tmap, texel=tmap.texel_size())
