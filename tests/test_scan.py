"""A user's scanned mesh and its texture: OBJ/PLY/GLB with UVs loaded and rendered end to
end, the shipped textured face, and every bad input one line, exit 2 (`jaxskin.scan`,
`jaxskin.mesh`)."""

from __future__ import annotations

import os
import shutil
import tomllib
import zlib
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from jaxskin.cli import main
from jaxskin.io import InputError
from jaxskin.mesh import BUILTIN, load_mesh, vertex_normals
from jaxskin.scan import check_texture
from jaxskin.scene import builtin_scenes, load_scene

ROOT = Path(__file__).resolve().parent.parent
MESHES = ROOT / "data" / "meshes"
SMALL = ["-D", "texture.size=32", "-D", "camera.size=24"]


def grid_obj(n: int = 4) -> str:
    """An n x n quad grid (a bump, in cm) with UVs: positions and UVs share indices."""
    lines = []
    for j in range(n + 1):
        for i in range(n + 1):
            u, v = i / n, j / n
            z = 2.0 * np.exp(-((u - 0.5) ** 2 + (v - 0.5) ** 2) * 4)
            lines.append(f"v {(u - 0.5) * 10:.4f} {(v - 0.5) * 10:.4f} {z:.4f}")
            lines.append(f"vt {u:.4f} {v:.4f}")
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i + 1
            b, c, d = a + 1, a + n + 2, a + n + 1
            lines += [f"f {a}/{a} {b}/{b} {c}/{c}", f"f {a}/{a} {c}/{c} {d}/{d}"]
    return "\n".join(lines) + "\n"


def textured_ball():
    """A trimesh icosphere with UVs and a 16² texture."""
    import trimesh

    s = trimesh.creation.icosphere(1)
    p = s.vertices
    uv = np.stack([0.5 + np.arctan2(p[:, 0], p[:, 2]) / (2 * np.pi), 0.5 + p[:, 1] / 2], 1)
    s.visual = trimesh.visual.TextureVisuals(uv=uv, image=Image.new("RGB", (16, 16),
                                                                    (200, 150, 120)))
    return s


def render(argv, capsys):
    capsys.readouterr()
    code = main(argv)
    return code, capsys.readouterr().err


# --- loading ---------------------------------------------------------------------------


@pytest.mark.parametrize("ext", ["glb", "ply", "obj"])
def test_a_textured_mesh_loads_with_its_uvs(tmp_path, ext):
    """trimesh's export of a textured mesh in each format loads with one UV per vertex, the
    same UVs (GLB and PLY keep the vertex order; OBJ may reorder, so compare as sets)."""
    ball = textured_ball()
    path = tmp_path / f"ball.{ext}"
    ball.export(path)
    m = load_mesh(path)
    assert m.uv is not None and m.uv.shape == (len(m.vertices), 2)
    got = {tuple(r) for r in np.round(np.c_[m.vertices, m.uv], 4)}
    want = {tuple(r) for r in np.round(np.c_[ball.vertices, ball.visual.uv], 4)}
    assert got == want


def test_a_glb_of_several_primitives_keeps_their_uvs(tmp_path):
    import trimesh

    a, b = textured_ball(), textured_ball()
    b.apply_translation([3.0, 0, 0])
    trimesh.Scene([a, b]).export(tmp_path / "two.glb")
    m = load_mesh(tmp_path / "two.glb")
    assert len(m.vertices) == 2 * len(a.vertices) and m.uv.shape == (len(m.vertices), 2)


def test_a_ply_with_uvs_per_corner_splits_its_seam_vertices(tmp_path):
    """MeshLab's PLY: UVs per face corner (`texcoord`); vertex 0 has two UVs."""
    (tmp_path / "c.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
        "property float z\nelement face 2\nproperty list uchar int vertex_indices\n"
        "property list uchar float texcoord\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n"
        "3 0 1 2 6 0 0 1 0 1 1\n3 0 2 3 6 0.5 0.5 1 1 0 1\n")
    m = load_mesh(tmp_path / "c.ply")
    assert len(m.vertices) == 5 and m.uv is not None
    corners = {tuple(r) for r in np.c_[m.vertices[m.faces[1]], m.uv[m.faces[1]]]}
    assert (0, 0, 0, 0.5, 0.5) in corners


def test_normals_are_welded_across_a_uv_seam(tmp_path):
    """An OBJ pyramid whose apex has two UVs (a seam) loads as two apex vertices; both get
    the normal of all four faces, (0, 0, 1) by symmetry, not each half's tilted one."""
    (tmp_path / "p.obj").write_text(
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 0.5 0.5\n"
        "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvt 0.5 0.5\nvt 0.9 0.9\n"
        "f 1/1 2/2 5/5\nf 2/2 3/3 5/5\nf 3/3 4/4 5/6\nf 4/4 1/1 5/6\n")
    m = load_mesh(tmp_path / "p.obj")
    apex = np.flatnonzero(m.vertices[:, 2] == 0.5)
    assert len(apex) == 2
    np.testing.assert_allclose(m.normals[apex], [[0, 0, 1]] * 2, atol=1e-12)
    unwelded = vertex_normals(m.vertices, m.faces)[apex]
    assert np.all(np.abs(unwelded[:, :2]).max(axis=1) > 0.3)  # the crease welding removes


@pytest.mark.parametrize("name", sorted(BUILTIN))
def test_built_in_meshes_normals_are_unchanged_by_welding(name):
    """No built-in mesh has two vertices at one position, so their renders do not move."""
    m = load_mesh(name)
    np.testing.assert_array_equal(m.normals, vertex_normals(m.vertices, m.faces))


def test_the_projection_defaults_to_the_meshs_own_uvs(tmp_path):
    """Unset: uv for a mesh with UVs, planar without; a set one is kept; each built-in scene
    says its projection, so none changes."""
    (tmp_path / "g.obj").write_text(grid_obj())
    (tmp_path / "n.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    for mesh, want in (("g.obj", "uv"), ("n.obj", "planar"), ("face", "uv"), ("hand", "planar")):
        (tmp_path / "s.toml").write_text(f'[mesh]\nfile = "{mesh}"\n')
        assert load_scene(tmp_path / "s.toml").values["mesh.projection"] == want, mesh
    assert load_scene(tmp_path / "s.toml", [f"mesh.file={tmp_path / 'g.obj'}", "mesh.projection=planar"]
                      ).values["mesh.projection"] == "planar"
    for name, path in builtin_scenes().items():
        assert "projection" in tomllib.loads(Path(path).read_text())["mesh"], name


# --- rendering -------------------------------------------------------------------------


def test_a_user_obj_with_its_texture_renders_end_to_end(tmp_path, capsys):
    """The shipped textured face as a user has it (OBJ + MTL + PNG, copied to their folder,
    named relative to the scene, no projection set) renders: its mesh is the built-in
    face's (same positions, UVs, faces), read through its MTL, its texture checked. (The
    render of the texture's colour is `skin.texture`'s: jaxskin skin-maps.)"""
    for ext in ("obj", "mtl", "png"):
        shutil.copy(MESHES / f"astronaut_face.{ext}", tmp_path / f"scan.{ext}")
    (tmp_path / "scan.obj").write_text((tmp_path / "scan.obj").read_text().replace(
        "astronaut_face.mtl", "scan.mtl"))
    (tmp_path / "scan.mtl").write_text((tmp_path / "scan.mtl").read_text().replace(
        "astronaut_face.png", "scan.png"))
    (tmp_path / "user.toml").write_text('name = "user"\n[mesh]\nfile = "scan.obj"\n'
                                        'unit_mm = 10.0\n')
    sc = load_scene(tmp_path / "user.toml")
    assert sc.values["mesh.projection"] == "uv"
    user, face = load_mesh(sc.values["mesh.file"]), load_mesh("face")
    for name in ("vertices", "uv", "faces", "normals"):
        np.testing.assert_array_equal(getattr(user, name), getattr(face, name))
    code, err = render(["render", str(tmp_path / "user.toml"), "-o", str(tmp_path / "out"),
                        *SMALL], capsys)
    assert code == 0, err
    image = np.asarray(Image.open(tmp_path / "out" / next(
        p.name for p in (tmp_path / "out").iterdir())))
    assert (image[..., :3].max(axis=-1) > 20).mean() > 0.3  # the face fills the frame
    info = check_texture(tmp_path / "scan.png")
    assert (info.width, info.height, info.mode, info.bits, info.notes) == (512, 512, "RGB", 8,
                                                                          ())


def test_the_shipped_face_is_small_and_its_texture_lines_up():
    """Under 1 MB; the texture's eyes are dark and the cheeks light at the UVs of MediaPipe's
    pupil-centre and cheek vertices (468 is not in the canonical model: the eye's centre is
    the mean of its corners 33 and 133)."""
    total = sum((MESHES / f"astronaut_face.{e}").stat().st_size for e in ("obj", "mtl", "png"))
    assert total < 1_000_000
    m = load_mesh(MESHES / "astronaut_face.obj")
    tex = np.asarray(Image.open(MESHES / "astronaut_face.png"), float).mean(axis=-1)

    def at(uv):
        return tex[int((1 - uv[1]) * 512), int(uv[0] * 512)]

    for a, b in ((33, 133), (263, 362)):
        eye = at((m.uv[a] + m.uv[b]) / 2)
        cheek = at(m.uv[50 if a == 33 else 280])
        assert eye < 0.6 * cheek, (eye, cheek)


# --- bad input -------------------------------------------------------------------------


def _mixed_glb(tmp):
    import trimesh

    trimesh.Scene([textured_ball(), trimesh.creation.box()]).export(tmp / "mixed.glb")
    return "mixed.glb"


def _no_uv_obj(tmp):
    (tmp / "n.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    return "n.obj"


def _fifo(tmp):
    os.mkfifo(tmp / "f.obj")
    return "f.obj"


def _link_to_fifo(tmp):
    os.mkfifo(tmp / "f.obj")
    os.symlink(tmp / "f.obj", tmp / "l.obj")
    return "l.obj"


def _folder(tmp):
    (tmp / "d.obj").mkdir()
    return "d.obj"


def _too_many_faces(tmp):
    (tmp / "g.obj").write_text(grid_obj(4))  # 32 triangles, over the limit of 10 set below
    return "g.obj"


@pytest.mark.parametrize("make, projection, words", [
    (_no_uv_obj, "uv", "key 'mesh.projection': mesh {tmp}/n.obj has no texture coordinates "
                       "(UVs); projection = \"uv\" needs them"),
    (_mixed_glb, "uv", "mixed.glb has no texture coordinates (UVs) (1 of its 2 parts have "
                       "none, and the parts are merged)"),
    (_fifo, None, "key 'mesh.file': not a regular file: {tmp}/f.obj"),
    (_link_to_fifo, None, "key 'mesh.file': not a regular file: {tmp}/f.obj"),
    (_folder, None, "key 'mesh.file': is a folder: {tmp}/d.obj"),
    (_too_many_faces, None, "g.obj: 32 triangles; at most 10 are rendered: decimate the scan "
                            "first, keeping its UVs"),
], ids=["no-uv", "glb-part-without-uv", "fifo", "symlink-to-fifo", "folder", "too-many-faces"])
def test_a_bad_mesh_is_one_line_exit_2(tmp_path, capsys, monkeypatch, make, projection,
                                       words):
    if make is _too_many_faces:
        monkeypatch.setattr("jaxskin.mesh.MAX_FACES", 10)
    mesh = make(tmp_path)
    text = f'[mesh]\nfile = "{mesh}"\n' + (f'projection = "{projection}"\n' if projection
                                           else "")
    (tmp_path / "s.toml").write_text(text)
    code, err = render(["render", str(tmp_path / "s.toml"), "-o", str(tmp_path / "out"),
                        *SMALL], capsys)
    lines = [line for line in err.splitlines() if not line.startswith("jaxskin: warning")]
    assert code == 2 and len(lines) == 1, err
    assert lines[0].startswith("jaxskin: error: ") and words.format(tmp=tmp_path) in lines[0]
    assert not (tmp_path / "out").exists()


def _png16_rgb(path):
    """A 16-bit RGB PNG written by hand (PIL reads one as 8-bit RGB without a word)."""
    raw = b"".join(b"\x00" + bytes(8 * 6) for _ in range(8))

    def chunk(kind, data):
        return (len(data).to_bytes(4, "big") + kind + data
                + zlib.crc32(kind + data).to_bytes(4, "big"))

    ihdr = (8).to_bytes(4, "big") * 2 + bytes([16, 2, 0, 0, 0])
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr)
                     + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def _texture(tmp, case):
    p = tmp / "t.png"
    if case == "wide":
        Image.new("RGB", (16, 8)).save(p)
    elif case == "rgb16":
        _png16_rgb(p)
    elif case == "grey16":
        Image.fromarray(np.zeros((8, 8), np.uint16)).save(p)
    elif case == "grey":
        Image.new("L", (8, 8)).save(p)
    elif case == "cmyk":
        p = tmp / "t.jpg"
        Image.new("CMYK", (8, 8)).save(p)
    elif case == "text":
        p.write_text("not an image")
    elif case == "fifo":
        os.mkfifo(p)
    elif case == "folder":
        p.mkdir()
    return p


@pytest.mark.parametrize("case, words", [
    ("wide", "16x8 pixels; expected a square texture"),
    ("grey16", "a greyscale image (I;16"),
    ("grey", "a greyscale image (L); expected a colour (RGB) texture"),
    ("cmyk", "a CMYK image; expected an RGB (sRGB) texture"),
    ("text", "cannot read as an image (UnidentifiedImageError"),
    ("fifo", "not a regular file (expected the scan's texture image)"),
    ("folder", "is a folder"),
    ("missing", "no such file"),
])
def test_a_bad_texture_is_refused_in_one_line(tmp_path, case, words):
    p = _texture(tmp_path, case)
    with pytest.raises(InputError) as e:
        check_texture(p, key="skin.texture")
    assert words in str(e.value) and "\n" not in str(e.value)
    assert "skin.texture" in str(e.value)


def test_a_16_bit_texture_is_read_at_full_depth_and_said(tmp_path):
    """PIL reads a 16-bit RGB PNG as 8-bit without a word: the header says 16, and so does
    the note (the inversion reads all 16 bits: `maps.read_image`)."""
    _png16_rgb(tmp_path / "t.png")
    info = check_texture(tmp_path / "t.png")
    assert info.bits == 16 and info.notes == (f"{tmp_path / 't.png'}: 16 bits per channel: "
                                              "read at full depth",)


def test_a_photo_need_not_be_square_for_skin_maps(tmp_path):
    """`square=False` (a photo given to `jaxskin skin-maps`): any aspect."""
    Image.new("RGB", (16, 8), (200, 150, 120)).save(tmp_path / "w.png")
    assert check_texture(tmp_path / "w.png", square=False).width == 16


def test_alpha_and_palette_textures_are_read_and_said(tmp_path):
    """RGBA (a quarter transparent) and a palette image: accepted, each with a note."""
    rgba = np.full((8, 8, 4), 255, np.uint8)
    rgba[:4, :4, 3] = 0
    Image.fromarray(rgba).save(tmp_path / "a.png")
    info = check_texture(tmp_path / "a.png", size=16)
    assert info.mode == "RGBA" and info.transparent == 0.25
    assert [n.split(": ", 1)[1] for n in info.notes] == [
        "has an alpha channel: its transparent texels (25%) are not skin; the colour is read "
        "as it is elsewhere", "8x8 resampled to texture.size 16"]
    Image.new("RGB", (8, 8), (200, 150, 120)).convert("P").save(tmp_path / "p.png")
    assert check_texture(tmp_path / "p.png").notes[-1].endswith("its colours are read as RGB")


def test_the_memory_estimate_counts_the_meshs_faces(tmp_path):
    """500 bytes a face over the texture's and image's part (measured 360: resources.py)."""
    from jaxskin import resources

    (tmp_path / "g.obj").write_text(grid_obj(8))  # 128 triangles
    (tmp_path / "s.toml").write_text('[mesh]\nfile = "g.obj"\n')
    with_mesh = resources.render_bytes(load_scene(tmp_path / "s.toml").config)
    (tmp_path / "n.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    one = resources.render_bytes(load_scene(tmp_path / "s.toml", [f"mesh.file={tmp_path / 'n.obj'}",
                                                                  "mesh.projection=uv"]).config)
    assert with_mesh - one == pytest.approx(127 * resources.PER_FACE)


def test_painting_in_the_editor_works_on_the_scan(tmp_path):
    """A brush stroke across the middle of the view of a user OBJ (the shipped textured
    face, referenced by path) paints its blush layer's map in the scan's texture space."""
    from jaxskin.editor import Session

    for ext in ("obj", "mtl", "png"):
        shutil.copy(MESHES / f"astronaut_face.{ext}", tmp_path / f"astronaut_face.{ext}")
    (tmp_path / "s.toml").write_text(
        'name = "scan"\n[mesh]\nfile = "astronaut_face.obj"\nunit_mm = 10.0\n[texture]\n'
        'size = 64\n[wrinkles]\nenabled = false\n[material]\nmodel = "spectral"\n[camera]\n'
        'size = 64\n[[layer]]\nname = "blush"\nmaterial = "blush_rose"\nthickness_mm = 0.02\n'
        '[[layer.ellipse]]\ncenter = [0.05, 0.95]\nradii = [0.02, 0.02]\n')  # a corner
    s = Session(str(tmp_path / "s.toml"), tmp_path / "out")
    assert s.scene.values["mesh.projection"] == "uv"
    s.paint_stroke("a", "blush", [[20.0, 32.0], [44.0, 32.0]], 3.0, 1.0)
    painted = np.asarray(s.paint["blush"]) > 0
    painted[:16, :16] = False  # the ellipse's corner
    assert painted.sum() > 20
    rows, cols = np.nonzero(painted)  # across the face's middle: the UVs' middle rows
    assert 0.3 < 1 - rows.mean() / 64 < 0.7 and 0.3 < cols.mean() / 64 < 0.7


def test_the_uv_maps_tangent_map_is_the_analytic_one():
    """A triangle whose UVs are its own (x, y), turned in 3D by R: the map from the surface
    to texture pixels is diag(size, −size) · Rᵀ (x right, y down) at every vertex, by hand;
    the closed-form pseudo-inverse that replaced numpy's SVD per face (7 s at 500k faces)
    must give it, for a thin sliver too."""
    from jaxskin.mesh import Mesh
    from jaxskin.projection import project

    a = np.radians(30.0)
    R = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]]) @ np.array(
        [[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    for leg in (1.0, 1e-4):  # a sliver: 10⁻⁴ as tall as wide
        flat = np.array([[0, 0, 0], [1, 0, 0], [0.4, leg, 0]], float)  # edges not at 90°
        uv = flat[:, :2]
        v = flat @ R.T
        mesh = Mesh("t", v, np.array([[0, 1, 2]]), np.tile(R[:, 2], (3, 1)), uv)
        tmap = project("uv", mesh, 100)
        want = np.array([[100.0, 0, 0], [0, -100.0, 0]]) @ R.T
        np.testing.assert_allclose(tmap.vector_map, np.broadcast_to(want, (3, 2, 3)),
                                   rtol=0, atol=1e-9 * 100 / leg)


# --- a scan's units ------------------------------------------------------------------------

@pytest.mark.parametrize("extent, unit_mm, expected", [
    (0.23, 1.0, "head.obj is 0.23 mm across, no body's or body part's size (20-2500 mm); "
                "the skin's subsurface scattering is computed in mm from it. In metres? "
                "mesh.unit_mm = 1000 makes it 230 mm"),
    (17.7, 1.0, "In centimetres? mesh.unit_mm = 10 makes it 177 mm"),
    (230.0, 1000.0, "head.obj is 2.3e+05 mm across, no body's or body part's size "
                    "(20-2500 mm); the skin's subsurface scattering is computed in mm from "
                    "it. In millimetres? mesh.unit_mm = 1 makes it 230 mm"),
    (9.0, 1.0, "In inches? mesh.unit_mm = 25.4 makes it 229 mm"),
    (1e-5, 1.0, "; set mesh.unit_mm to the millimetres one mesh unit is"),
    (17.7, 10.0, None), (1.8, 1000.0, None), (0.02, 1000.0, None), (2.5, 1000.0, None),
], ids=["metres", "centimetres", "millimetres-read-as-metres", "inches", "none-fits", "face",
        "body", "lip-patch", "2.5-m"])
def test_a_mesh_of_no_bodys_size_is_warned_with_the_unit_that_fits(extent, unit_mm,
                                                                     expected):
    """The sizes by hand: 0.23 m × 1000 = 230 mm, 17.7 cm × 10 = 177 mm, 9 in × 25.4 =
    228.6 mm; of the units that fit, the one nearest a head's 250 mm (17.7 in metres would
    be 17.7 m, outside)."""
    from jaxskin.checks import size_warning

    got = size_warning("head.obj", extent, unit_mm)
    if expected is None:
        assert got is None
    else:
        assert got is not None and got.startswith(f"mesh.unit_mm = {unit_mm:g}: ")
        assert got.endswith(expected), got


def test_a_scan_in_metres_is_warned_only_where_its_size_is_read(tmp_path, capsys):
    """The shipped face (cm) said to be in mm: the spectral face's render warns once and
    still renders; with `sss.texel_mm` set (the size is not read from the mesh), with the
    blur off, or the Blinn model, nothing is said about it."""
    import warnings

    from jaxskin.checks import check_scene

    def warned(*extra):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_scene(load_scene("face", ["mesh.unit_mm=1", *extra]), 1)
        return [str(w.message) for w in caught if "mesh.unit_mm" in str(w.message)]

    assert warned("sss.texel_mm=0.2") == []
    assert warned("sss.enabled=false") == []
    assert warned("material.model=blinn") == []
    assert warned("mesh.unit_mm=10") == []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code, err = render(["render", "face", "-o", str(tmp_path / "out"), *SMALL,
                            "-D", "mesh.unit_mm=1"], capsys)
    assert code == 0, err
    lines = [str(w.message) for w in caught if "mesh.unit_mm" in str(w.message)]
    assert len(lines) == 1 and lines[0].startswith("mesh.unit_mm = 1: face is 17.7 mm "
                                                   "across"), lines
    assert lines[0].endswith("In centimetres? mesh.unit_mm = 10 makes it 177 mm"), lines
    assert len(list((tmp_path / "out").glob("*.png"))) == 1
