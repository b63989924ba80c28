"""Cut the foot and arm meshes out of the SMPL body (data/meshes/human_man.obj).

    python data/make_meshes.py      # writes data/meshes/foot.obj and data/meshes/arm.obj

The body (CC BY 4.0, Max Planck Society e.V. via SMPL; see meshes/human_README.md) stands
in a T-pose, y up, facing +z, in metres. We keep the faces whose three vertices lie in a
box (each box holds one limb and nothing else), and turn it to suit the paper's projections:

- foot: the right foot below the ankle (y < 0.10 m, x > 0), turned so that its top faces
  the viewer (+z) and the toes point up (+y): planar projection, like Bando's fig. 6.2.
  The cut at the ankle is capped (`cap_holes`: a low dome over each boundary loop), so that
  the open leg is not seen as a dark cavity;
- arm: the right arm from below the shoulder to the wrist (0.30 m < x < 0.70 m), turned so
  that its axis is the y axis through the origin: cylindrical projection, like fig. 6.3.
  Its two ends are cut square across the axis (`square_ends`), so that the side view shows
  a clean outline at the wrist and the shoulder, not the zigzag of the box's whole faces.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

HERE = Path(__file__).resolve().parent / "meshes"


def cut(body: trimesh.Trimesh, keep_vertex) -> trimesh.Trimesh:
    """The faces whose vertices all satisfy `keep_vertex` (each box holds one limb only)."""
    inside = keep_vertex(body.vertices)
    faces = np.flatnonzero(inside[body.faces].all(axis=1))
    return body.submesh([faces], append=True)


def boundary_edges(m: trimesh.Trimesh) -> np.ndarray:
    """The edges `(a, b)` that only one face has, as that face runs (the open rims)."""
    directed = np.asarray(m.faces)[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    _, inverse, counts = np.unique(np.sort(directed, axis=1), axis=0, return_inverse=True,
                                   return_counts=True)
    return directed[counts[inverse.ravel()] == 1]


def cap_holes(m: trimesh.Trimesh, rings: int = 3, bulge: float = 0.35) -> trimesh.Trimesh:
    """Close every boundary loop with a low dome: `rings` rings shrinking towards the loop's
    centroid, raised along the loop's plane normal (away from the part) by `bulge` × the
    loop's mean radius × (1 − r²), then a fan; wound like the faces beside it (a boundary
    edge a → b of a face gives the cap's b → a → …). A flat fan would read as a cut."""
    faces = np.asarray(m.faces)
    following = {int(a): int(b) for a, b in boundary_edges(m)}
    vertices, new_faces = [np.asarray(m.vertices)], [faces]
    count = len(m.vertices)
    while following:
        start = next(iter(following))
        loop = [start]
        while following[loop[-1]] != start:
            loop.append(following.pop(loop[-1]))
        following.pop(loop[-1])
        outer = np.asarray(loop)
        rim = m.vertices[outer]
        centre = rim.mean(axis=0)
        normal = np.linalg.svd(rim - centre)[2][2]
        if normal @ (centre - m.vertices.mean(axis=0)) < 0:
            normal = -normal
        height = bulge * np.linalg.norm(rim - centre, axis=1).mean()
        for k in range(1, rings + 1):
            r = 1 - k / (rings + 1)
            ring = centre + r * (rim - centre) + height * (1 - r * r) * normal
            inner = count + np.arange(len(outer))
            vertices.append(ring)
            count += len(outer)
            nxt_o, nxt_i = np.roll(outer, -1), np.roll(inner, -1)
            new_faces += [np.stack([nxt_o, outer, inner], 1), np.stack([nxt_o, inner, nxt_i], 1)]
            outer = inner
        vertices.append((centre + height * normal)[None])
        new_faces.append(np.stack([np.roll(outer, -1), outer, np.full(len(outer), count)], 1))
        count += 1
    return trimesh.Trimesh(np.concatenate(vertices), np.concatenate(new_faces), process=False)


def foot(body):
    m = cut(body, lambda v: (v[:, 1] < 0.10) & (v[:, 0] > 0.0))
    v = m.vertices
    # (x, y, z) -> (-x, z, y): top of the foot (+y) to +z, toes (+z) to +y. A proper rotation.
    m.vertices = np.stack([-v[:, 0], v[:, 2], v[:, 1]], axis=1)
    m.vertices -= m.bounds.mean(axis=0)
    return cap_holes(m)  # after centring: the foot's own vertices stay where they were


def arm(body):
    m = cut(body, lambda v: (v[:, 0] > 0.30) & (v[:, 0] < 0.70))
    v = m.vertices - m.vertices.mean(axis=0)
    # Principal axis -> y; the rotation keeps the handedness.
    _, _, vt = np.linalg.svd(v, full_matrices=False)
    axis = vt[0] if vt[0][0] < 0 else -vt[0]  # shoulder (small x) up
    third = np.cross(axis, vt[1])
    R = np.stack([vt[1], axis, third])
    if np.linalg.det(R) < 0:
        R[0] = -R[0]
    m.vertices = v @ R.T
    return square_ends(m)


def square_ends(m: trimesh.Trimesh) -> trimesh.Trimesh:
    """Cut a limb's ragged ends (the box keeps whole faces, so each end is a zigzag of
    triangles) with planes across its axis (y), just inside the zigzag: a side view then
    sees each open end edge-on, as a straight line, not as a notch into the cavity."""
    y = m.vertices[np.unique(boundary_edges(m)), 1]
    low, high = y[y < 0].max(), y[y > 0].min()  # the inner ends of the two zigzags
    for origin, normal in ((low, 1.0), (high, -1.0)):
        v, f = trimesh.intersections.slice_faces_plane(m.vertices, m.faces, [0.0, normal, 0.0],
                                                       [0.0, origin, 0.0])[:2]
        m = trimesh.Trimesh(v, f, process=False)
    m.merge_vertices()  # the slice gives each cut triangle its own new vertices
    m.remove_unreferenced_vertices()
    return m


def main():
    body = trimesh.load(HERE / "human_man.obj", process=False)
    header = ("# Cut from human_man.obj (SMPL, Max Planck Society e.V., CC BY 4.0) by "
              "data/make_meshes.py; modified: cut and rotated (the foot capped, the arm's "
              "ends squared).\n")
    for name, make in (("foot", foot), ("arm", arm)):
        mesh = make(body)
        text = header + trimesh.exchange.obj.export_obj(mesh, include_normals=False,
                                                         include_texture=False)
        tmp = HERE / f".{name}.obj.tmp"
        tmp.write_text(text)
        tmp.replace(HERE / f"{name}.obj")
        print(f"{name}: {len(mesh.vertices)} vertices, {len(mesh.faces)} faces, "
              f"bounds {np.round(mesh.bounds, 3).tolist()}")


if __name__ == "__main__":
    main()
