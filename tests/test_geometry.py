"""Meshes, the rasterizer, projections and direction fields."""

import math
import warnings

import jax.numpy as jnp
import numpy as np
import pytest

from jaxskin.fields import Edit, initial_fields, interpolate_fields
from jaxskin.io import InputError
from jaxskin.mesh import load_mesh
from jaxskin.projection import cylinder_to_xyz, project
from jaxskin.raster import interpolate, rasterize


def test_two_triangles_cover_a_pixel_aligned_square_once():
    xy = np.array([[2.0, 3.0], [6.0, 3.0], [6.0, 8.0], [2.0, 8.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    r = rasterize(xy, faces, 10, 10)
    assert r.mask.sum() == 4 * 5  # pixel centres 2.5..5.5 x 3.5..7.5, none twice, no gap
    assert set(np.unique(r.tri[r.mask])) == {0, 1}
    assert np.all(r.mask[3:8, 2:6])
    np.testing.assert_allclose(r.bary[r.mask].sum(axis=1), 1.0, rtol=1e-6)


def test_nearest_triangle_wins_where_they_overlap():
    xy = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]] * 2)
    faces = np.array([[0, 1, 2], [3, 4, 5]])
    for depth, winner in (([2, 2, 2, 1, 1, 1], 1), ([1, 1, 1, 2, 2, 2], 0)):
        r = rasterize(xy, faces, 10, 10, depth=np.array(depth, float))
        assert set(np.unique(r.tri[r.mask])) == {winner}


def test_a_triangle_across_the_cylinder_seam_wraps():
    xy = np.array([[30.0, 2.0], [34.0 - 32.0, 2.0], [32.0 - 32.0 + 1.0, 8.0]])  # x 30 -> 2 -> 1
    r = rasterize(xy, np.array([[0, 1, 2]]), 10, 32, wrap_x=True)
    cols = np.unique(np.nonzero(r.mask)[1])
    assert set(cols) <= {30, 31, 0, 1} and {31, 0} <= set(cols)
    assert r.mask.sum() < 20  # drawn across the seam, not across the whole image


def test_interpolation_of_a_linear_attribute_is_exact():
    xy = np.array([[1.0, 1.0], [15.0, 2.0], [3.0, 14.0]])
    faces = np.array([[0, 1, 2]])
    r = rasterize(xy, faces, 16, 16)
    got = interpolate(jnp.asarray(xy, jnp.float32), faces, r)
    ii, jj = np.nonzero(r.mask)
    np.testing.assert_allclose(np.asarray(got)[ii, jj], np.stack([jj + 0.5, ii + 0.5], 1),
                               atol=1e-5)  # float32: measured 9.5e-7


def test_cylindrical_projection_round_trips():
    mesh = load_mesh("arm")
    tm = project("cylindrical", mesh, 512)
    s = tm.xy[:, 0] / tm.width * 2 * math.pi
    r = np.hypot(mesh.vertices[:, 0], mesh.vertices[:, 2])
    texel = 2 * math.pi * r.mean() / tm.width
    lo, hi = mesh.vertices[:, 1].min(), mesh.vertices[:, 1].max()
    t = (tm.height / 2 - tm.xy[:, 1]) * texel + (lo + hi) / 2
    np.testing.assert_allclose(cylinder_to_xyz(s, t, r), mesh.vertices, atol=1e-9)
    # A vector along the circumference maps to +x, one along the axis to -y (rows down).
    n = len(mesh.vertices)
    around = np.stack([np.cos(s), np.zeros(n), -np.sin(s)], 1)
    np.testing.assert_allclose(tm.vectors(around), np.tile([1.0, 0.0], (n, 1)), atol=1e-9)
    np.testing.assert_allclose(tm.vectors(np.tile([0, 1.0, 0], (n, 1))),
                               np.tile([0.0, -1.0], (n, 1)), atol=1e-9)
    assert tm.raster.mask.mean() > 0.8  # the seam leaves no gap


def test_planar_projection_keeps_the_front_side():
    mesh = load_mesh("hand")
    tm = project("planar", mesh, 256)
    tri = tm.raster.tri[tm.raster.mask]
    assert np.mean(mesh.face_normals()[tri, 2] > 0) > 0.95


def test_initial_fields_and_exact_edits():
    mesh = load_mesh("hand")
    d1, d2 = initial_fields(mesh)
    np.testing.assert_allclose(np.sum(d1 * mesh.normals, 1), 0, atol=1e-12)
    np.testing.assert_allclose(d2, np.cross(d1, mesh.normals))
    n = mesh.normals
    # Edits given tangent at their vertex are reproduced exactly there.
    picks = [10, 300, 700]
    edits = []
    for k, v in enumerate(picks):
        t = np.cross(n[v], [0.3, 0.1, 0.9 + k])
        t = t / np.linalg.norm(t) * (0.5 + 0.5 * k)
        edits.append(Edit(v, tuple(t), tuple(-0.7 * t), weight=1 + k))
    f1, f2 = interpolate_fields(mesh, edits)
    for e in edits:
        np.testing.assert_allclose(f1[e.vertex], e.d1, atol=1e-12)
        np.testing.assert_allclose(f2[e.vertex], e.d2, atol=1e-12)
    np.testing.assert_allclose(np.sum(f1 * n, 1), 0, atol=1e-9)  # tangent everywhere
    mags = np.linalg.norm(f1, axis=1)
    assert mags.min() >= 0.5 - 1e-9 and mags.max() <= 1.5 + 1e-9  # between the edits'


def test_zero_weight_edit_is_exact_at_itself_only():
    mesh = load_mesh("hand")
    t = np.cross(mesh.normals[5], [0, 0, 1.0])
    base = [Edit(400, tuple(np.cross(mesh.normals[400], [1, 0, 0.0])), (0.0, 0.0, 0.0), 1.0)]
    with_zero = base + [Edit(5, tuple(t), tuple(t), 0.0)]
    a, _ = interpolate_fields(mesh, base)
    b, _ = interpolate_fields(mesh, with_zero)
    others = np.setdiff1d(np.arange(len(a)), [5])
    np.testing.assert_allclose(a[others], b[others], atol=1e-12)
    np.testing.assert_allclose(b[5], t / np.linalg.norm(t) * np.linalg.norm(t), atol=1e-12)


BAD_MESHES = [
    ("empty.obj", "", "empty"),
    ("points.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n", "empty"),
    ("flat.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", "degenerate"),
    ("garbage.stl", "this is not a mesh", "empty"),  # trimesh reads it as no triangles
]


@pytest.mark.parametrize("name, text, words", BAD_MESHES)
def test_bad_meshes_are_clear_errors(tmp_path, name, text, words):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(InputError, match=words) as info:
        load_mesh(path)
    assert str(path) in str(info.value)


def test_degenerate_faces_are_removed_with_a_warning(tmp_path):
    path = tmp_path / "quad.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\n"
                    "f 1 2 3 4\nf 1 2 5\n")  # a quad (triangulated) and a zero-area triangle
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mesh = load_mesh(path)
    assert len(mesh.faces) == 2
    assert any("degenerate" in str(w.message) for w in caught)
    with pytest.raises(InputError, match="no such mesh"):
        load_mesh(tmp_path / "missing.obj")


def _tube(path, around=24, along=8, split_seam=True, reverse=False):
    """An open tube (radius 1, length 4 along y) with UVs u = angle / 2π, v = y: the seam's
    vertices split (u = 1 beside u = 0) or shared (the last quad runs from u ≈ 1 to u = 0);
    outward winding, or reversed."""
    n = around + 1 if split_seam else around
    rows = []
    for j in range(along + 1):
        for i in range(n):
            a = 2 * math.pi * i / around
            rows.append((math.sin(a), 4.0 * j / along - 2.0, math.cos(a), i / around,
                         j / along))
    faces = []
    for j in range(along):
        for i in range(around):
            a, b = j * n + i, j * n + (i + 1) % n
            c, d = a + n, b + n
            faces += [(a, b, d), (a, d, c)]
    faces = np.asarray(faces) + 1
    if reverse:
        faces = faces[:, ::-1]
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z, _, _ in rows]
    lines += [f"vt {u:.6f} {v:.6f}" for *_, u, v in rows]
    lines += [f"f {a}/{a} {b}/{b} {c}/{c}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_mesh_wound_inward_is_turned_outward_once_with_a_warning(tmp_path):
    """A tube whose triangles wind inward (normals into the body: it would render flat and
    dark with no word) loads with its faces reversed, one warning for the
    file however often it is loaded, and the same vertex normals as the tube wound right.
    The built-in meshes (open at the wrist, cut, a face's shell) are left as they are: their
    signed volume measured +0.12 to +0.35 of their box."""
    from jaxskin.mesh import signed_volume

    good = load_mesh(_tube(tmp_path / "good.obj"))
    path = _tube(tmp_path / "inward.obj", reverse=True)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        bad = load_mesh(path)
        load_mesh(path)
    said = [str(w.message) for w in caught]
    assert len(said) == 1 and "wind inward" in said[0] and str(path) in said[0], said
    assert np.allclose(bad.normals, good.normals)
    assert signed_volume(good.vertices, good.faces) > 0.4
    for name in ("hand", "hand_closed", "foot", "arm", "face"):
        m = load_mesh(name)
        assert 0.1 < signed_volume(m.vertices, m.faces) < 0.4, name


def test_uv_seam_with_shared_vertices_wraps_like_a_split_one(tmp_path):
    """A tube's UVs with the seam's vertices shared: the last column of triangles runs from
    u ≈ 1 back to 0 and must not be drawn across every row of the texture (scrambled
    normals). It is read as a wrap in u, with a warning: the texture's mask equals
    that of the same tube with the seam split, and its normals are the cylinder's."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        shared = project("uv", load_mesh(_tube(tmp_path / "shared.obj", split_seam=False)), 48)
    assert any("span more than half the texture in u" in str(w.message) for w in caught)
    split = project("uv", load_mesh(_tube(tmp_path / "split.obj")), 48)
    assert shared.wrap_x and not split.wrap_x
    assert np.array_equal(shared.raster.mask, split.raster.mask)
    assert shared.raster.mask.mean() > 0.75
    # the normals it interpolates against the cylinder's own, (sin 2πu, 0, cos 2πu):
    # within the 24-gon's facets (measured 2.3°; scrambled across the texture before)
    n = np.asarray(interpolate(shared.mesh.normals.astype(np.float32), shared.mesh.faces,
                               shared.raster))
    u = (np.arange(48) + 0.5) / 48
    true = np.stack([np.sin(2 * np.pi * u), 0 * u, np.cos(2 * np.pi * u)], axis=1)[None]
    m = shared.raster.mask
    cos = (n * true).sum(-1)[m] / np.linalg.norm(n, axis=-1)[m]
    assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 4.0


@pytest.mark.parametrize("around", [3, 4, 5])
def test_a_low_poly_tube_seam_wraps_too(tmp_path, around):
    """An N-sided tube's seam face spans (N-1)/N of the texture, only N-1 times its
    neighbours: still a seam (a rule on stretch alone missed N ≤ 5 and smeared it again).
    A square over the whole texture, which is no seam, is test_makeup's texel-size test."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        shared = project("uv", load_mesh(_tube(tmp_path / "s.obj", around, split_seam=False)),
                         48)
    said = [str(w.message) for w in caught if "span more than half" in str(w.message)]
    assert said == [f"mesh 's': {2 * 8} triangles span more than half the texture in u: read "
                    "as a seam where u wraps from 1 back to 0 (the texture wraps in u)"]
    split = project("uv", load_mesh(_tube(tmp_path / "t.obj", around)), 48)
    assert shared.wrap_x and not split.wrap_x
    assert np.array_equal(shared.raster.mask, split.raster.mask)


def test_a_uv_seam_does_not_wrap_a_wide_face_that_is_no_seam(tmp_path):
    """A UV map with a seam (a tube whose seam vertices are shared, v in [0, 0.45]) and a
    flat panel mapped across u 0.05-0.95 (v 0.55-0.95) at the tube's texels per unit: the
    panel's two triangles span more than half the texture but are no seam. Once the seam
    turned wrapping on, every face that wide was drawn the short way round, across the cut:
    the panel's middle was left empty."""
    path = _tube(tmp_path / "t.obj", split_seam=False)
    lines = path.read_text().splitlines()
    nv = sum(line.startswith("v ") for line in lines)
    scale = 2 * math.pi  # the tube: u 1 over 2π units; the panel at the same texels per unit
    panel = [(-0.45 * scale, 1.0, 3.0, 0.05, 0.55), (0.45 * scale, 1.0, 3.0, 0.95, 0.55),
             (0.45 * scale, 1.0 + 0.4 * scale, 3.0, 0.95, 0.95),
             (-0.45 * scale, 1.0 + 0.4 * scale, 3.0, 0.05, 0.95)]
    verts = [line for line in lines if line.startswith("v ")]
    verts += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z, _, _ in panel]
    uvs = [f"vt {float(u):.6f} {float(v) * 0.45:.6f}"  # the tube in v 0-0.45
           for _, u, v in (line.split() for line in lines if line.startswith("vt "))]
    uvs += [f"vt {u:.6f} {v:.6f}" for *_, u, v in panel]
    faces = [line for line in lines if line.startswith("f ")]
    a, b, c, d = (nv + k for k in (1, 2, 3, 4))
    faces += [f"f {a}/{a} {b}/{b} {c}/{c}", f"f {a}/{a} {c}/{c} {d}/{d}"]
    (tmp_path / "both.obj").write_text("\n".join(verts + uvs + faces) + "\n")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        tmap = project("uv", load_mesh(tmp_path / "both.obj"), 48)
    said = [str(w.message) for w in caught if "span more than half" in str(w.message)]
    assert len(said) == 1 and "16 triangles" in said[0], said  # the tube's seam column only
    assert tmap.wrap_x
    F = len(tmap.mesh.faces)
    tri = tmap.raster.tri
    rows, cols = slice(round(0.1 * 48), round(0.4 * 48)), slice(round(0.1 * 48), round(0.9 * 48))
    assert np.all(tri[rows, cols] >= F - 2)  # the panel's middle: its own two triangles
    corners = tmap.face_corners()[F - 2:]
    assert corners[..., 0].min() >= 0.05 * 48 - 1e-9 and corners[..., 0].max() <= 0.95 * 48
