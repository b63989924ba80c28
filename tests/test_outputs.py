"""What other tools read: 16-bit PNG, linear OpenEXR and alpha from `jaxskin render`."""

import subprocess

import imageio.v3 as iio
import numpy as np
import pytest

from jaxskin import maps, render
from jaxskin.scene import load_scene

SMALL = ["texture.size=64", "camera.size=32"]


def _render(tmp_path, *options):
    """`jaxskin render face` at SMALL sizes, in this process (the command's `main`: the
    module's renders share their compiled programs instead of each starting a process)."""
    from jaxskin.cli import main

    out = tmp_path / "out"
    args = ["render", "face", "-o", str(out)]
    for o in SMALL:
        args += ["-D", o]
    assert main([*args, *options]) == 0
    return out


def _written(out, ext):
    """The one image the render wrote (its name carries the -D overrides)."""
    (path,) = out.glob(f"face*.{ext}")
    return path


@pytest.fixture(scope="module")
def face():
    sc = load_scene("face", SMALL)
    return sc, np.asarray(render.render(sc.config, sc.params, "rgba"))


def test_png16_is_the_8_bit_png_to_within_rounding(tmp_path, face):
    out8 = _render(tmp_path / "a", "--alpha")
    out16 = _render(tmp_path / "b", "--alpha", "--format", "png16")
    png = pytest.importorskip("png", reason="pypng (the test extra) reads 16-bit colour")
    a = iio.imread(_written(out8, "png"))
    width, height, rows, info = png.Reader(filename=str(_written(out16, "png"))).asDirect()
    assert info["bitdepth"] == 16 and info["alpha"] and (width, height) == (32, 32)
    b = np.vstack([np.asarray(r, np.uint16) for r in rows]).reshape(32, 32, 4)
    assert a.dtype == np.uint8 and b.dtype == np.uint16 and a.shape == b.shape == (32, 32, 4)
    # Both round the same value: |b / 257 - a| <= 0.5 + 0.5 / 257 (one rounding each).
    assert np.abs(b / 257.0 - a).max() <= 0.5 + 0.5 / 257 + 1e-9
    # And the 16-bit file holds the render to 16-bit precision.
    np.testing.assert_allclose(b / 65535.0, np.clip(face[1], 0, 1), atol=0.5 / 65535 + 1e-7)
    plain = iio.imread(_written(_render(tmp_path / "c"), "png"))
    assert plain.shape == (32, 32, 3)  # no --alpha: RGB as before


def test_exr_holds_the_linear_render_with_alpha(tmp_path, face):
    pytest.importorskip("OpenEXR", reason="the exr extra (pip install 'jaxskin[exr]')")
    sc, rgba = face
    out = _render(tmp_path, "--format", "exr")
    exr = maps.read_exr(_written(out, "exr"))
    linear = np.asarray(render.render(sc.config, sc.params, "linear_rgba"))
    np.testing.assert_array_equal(exr, linear)  # float32, lossless (ZIP)
    # The linear light is the display image before encoding (over black).
    display = np.asarray(render.render(sc.config, sc.params))
    np.testing.assert_allclose(render.encode_srgb(exr[..., :3]), display, atol=2e-6)
    alpha = exr[..., 3]
    mask = render.prepare(sc.config).view.mask
    k = sc.config.supersample
    blocks = mask.reshape(32, k, 32, k)
    assert np.all(alpha[~blocks.any(axis=(1, 3))] == 0)  # background
    assert np.all(alpha[blocks.all(axis=(1, 3))] == 1)  # inside
    edge = (alpha > 0) & (alpha < 1)
    assert edge.sum() > 10  # antialiased silhouette
    assert np.all(exr[alpha == 0, :3] == 0)


def test_exr_without_the_bindings_is_an_input_error(tmp_path, monkeypatch):
    from jaxskin import cli

    monkeypatch.setattr(maps, "exr_available", lambda: False)
    assert cli.main(["render", "face", "-o", str(tmp_path / "x"), "--format", "exr"]) == 2
    assert not (tmp_path / "x").exists()


@pytest.fixture(scope="module")
def glbs(tmp_path_factory):
    """GLBs of the arm (cylinder: a seam), the hand (planar: both sides) and the face (UV),
    with what they were made from."""
    from jaxskin import texture
    from jaxskin.export import glb_bytes

    out = {}
    for name in ("arm", "hand", "face"):
        sc = load_scene(name, ["texture.size=128", "camera.size=16"])
        s = texture.setup(sc.config.texture)
        normals = np.asarray(texture.texture_maps(sc.config, sc.params)["normals"])
        data = glb_bytes(s, np.asarray(render.albedo(sc.config, sc.params)), normals)
        path = tmp_path_factory.mktemp("glb") / f"{name}.glb"
        path.write_bytes(data)
        out[name] = (path, s, normals)
    return out


def _accessor(doc, blob, i):
    a = doc["accessors"][i]
    v = doc["bufferViews"][a["bufferView"]]
    dtype = {5126: np.float32, 5125: np.uint32}[a["componentType"]]
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[a["type"]]
    data = np.frombuffer(blob, dtype, a["count"] * width, v["byteOffset"])
    return data.reshape(a["count"], width) if width > 1 else data


def test_glb_structure(glbs):
    """What the Khronos validator checks that matters here, in Python (the validator
    itself runs in the next test where node has it): POSITION bounds exact, unit normals
    and tangents, w = ±1, 4-byte aligned views, indices in range, PNG images. Not checked
    here: the PNGs' insides, the JSON schema's every rule, animation/skin rules (none)."""
    from jaxskin.export import read_glb

    for name, (path, _, _) in glbs.items():
        doc, blob = read_glb(path.read_bytes())
        prim = doc["meshes"][0]["primitives"][0]
        assert set(prim["attributes"]) == {"POSITION", "NORMAL", "TANGENT", "TEXCOORD_0"}
        for v in doc["bufferViews"]:
            assert v["byteOffset"] % 4 == 0 and v["byteOffset"] + v["byteLength"] <= len(blob)
        pos = _accessor(doc, blob, prim["attributes"]["POSITION"])
        a = doc["accessors"][prim["attributes"]["POSITION"]]
        assert a["min"] == pos.min(axis=0).tolist() and a["max"] == pos.max(axis=0).tolist()
        n = _accessor(doc, blob, prim["attributes"]["NORMAL"])
        t = _accessor(doc, blob, prim["attributes"]["TANGENT"])
        np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1, atol=1e-6)
        np.testing.assert_allclose(np.linalg.norm(t[:, :3], axis=1), 1, atol=1e-6)
        assert set(np.unique(t[:, 3])) <= {-1.0, 1.0}
        assert np.abs(np.sum(n * t[:, :3], axis=1)).max() < 1e-5  # orthogonal
        idx = _accessor(doc, blob, prim["indices"])
        assert idx.max() < len(pos) and len(idx) % 3 == 0
        for image in doc["images"]:
            v = doc["bufferViews"][image["bufferView"]]
            assert blob[v["byteOffset"]:v["byteOffset"] + 8] == b"\x89PNG\r\n\x1a\n"
        if name == "hand":  # planar: u = x, v = −y; the back side is mirrored
            front, back = n[:, 2] > 0.9, n[:, 2] < -0.9
            assert np.all(t[front, 0] > 0.9) and np.all(t[back, 0] > 0.9)
            assert np.all(t[front, 3] == 1) and np.all(t[back, 3] == -1)
        if name == "arm":  # cylindrical: u grows with the angle s from +z about y
            p = pos.astype(np.float64)
            circ = np.stack([p[:, 2], 0 * p[:, 0], -p[:, 0]], 1)  # ∂P/∂s ∝ (cos s, 0, −sin s)
            circ /= np.linalg.norm(circ, axis=1, keepdims=True)
            assert np.median(np.sum(t[:, :3] * circ, axis=1)) > 0.99
            assert np.all(t[:, 3] == 1)


def test_tangents_of_a_plane_by_hand():
    """A unit square in z = 0 with u = x, v = 1 − y (glTF's v runs down): tangent +x,
    "up" (decreasing v) is +y = cross(+z, +x), so w = +1; mirrored in u, w = −1."""
    from jaxskin.export import vertex_tangents

    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    n = np.tile([0.0, 0.0, 1.0], (4, 1))
    uv = np.stack([v[:, 0], 1 - v[:, 1]], 1)[f]
    np.testing.assert_allclose(vertex_tangents(v, f, uv, n), np.tile([1, 0, 0, 1.0], (4, 1)))
    mirrored = uv * [-1, 1]
    np.testing.assert_allclose(vertex_tangents(v, f, mirrored, n),
                               np.tile([-1, 0, 0, -1.0], (4, 1)))


def test_glb_passes_the_khronos_validator(glbs, tmp_path):
    """The Khronos glTF validator (npm `gltf-validator`, installed globally) finds no
    error and no warning (infos allowed: the arm's texture is 128 × 218, not a power
    of two)."""
    import json
    import shutil

    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed (the glTF validator is a JavaScript package)")
    root = subprocess.run(["npm", "root", "-g"], capture_output=True, text=True).stdout.strip() \
        if shutil.which("npm") else ""
    env = {"NODE_PATH": root, "PATH": "/usr/bin:/bin"}
    if subprocess.run([node, "-e", "require('gltf-validator')"], env=env,
                      capture_output=True).returncode != 0:
        pytest.skip("the npm package gltf-validator is not installed (npm install -g "
                    "gltf-validator)")
    script = (
        "const fs = require('fs'); const v = require('gltf-validator');"
        "(async () => { const out = {}; for (const f of process.argv.slice(1)) {"
        " const r = await v.validateBytes(new Uint8Array(fs.readFileSync(f)));"
        " out[f] = {errors: r.issues.numErrors, warnings: r.issues.numWarnings,"
        " messages: r.issues.messages.map(m => m.severity + ' ' + m.code)}; }"
        " console.log(JSON.stringify(out)); })();")
    paths = [str(p) for p, _, _ in glbs.values()]
    proc = subprocess.run([node, "-e", script, *paths], env=env, capture_output=True,
                          text=True)
    assert proc.returncode == 0, proc.stderr
    for path, result in json.loads(proc.stdout).items():
        assert result["errors"] == 0 and result["warnings"] == 0, (path, result)


@pytest.mark.parametrize("name", ["arm", "hand", "face"])
def test_glb_normal_map_rebuilds_the_bumped_normals(glbs, name):
    """A viewer's reconstruction from the file (vertex NORMAL and TANGENT interpolated
    over each triangle in UV space, bitangent = cross(n, t) w, the normal texture decoded)
    gives back the renderer's bumped normals to 8-bit precision (|Δ| < 0.02 at the 99th
    percentile; measured 0.0055–0.0059 on the three meshes; one 8-bit step is 0.008)."""
    from jaxskin.export import read_glb
    from jaxskin.raster import rasterize

    path, s, normals = glbs[name]
    doc, blob = read_glb(path.read_bytes())
    prim = doc["meshes"][0]["primitives"][0]
    uv = _accessor(doc, blob, prim["attributes"]["TEXCOORD_0"])
    n = _accessor(doc, blob, prim["attributes"]["NORMAL"])
    t = _accessor(doc, blob, prim["attributes"]["TANGENT"])
    faces = _accessor(doc, blob, prim["indices"]).reshape(-1, 3)
    H, W = s.tmap.height, s.tmap.width
    pos = _accessor(doc, blob, prim["attributes"]["POSITION"])
    depth = -pos[:, 2] if name == "hand" else None  # planar: the front side owns the texels
    r = rasterize(uv * [W, H], faces, H, W, depth=depth, wrap_x=s.tmap.wrap_x)
    inside = r.mask & np.asarray(s.mask)
    tri, bary = r.tri[inside], r.bary[inside][..., None]
    N = (bary * n[faces[tri]]).sum(axis=1)
    T = (bary * t[faces[tri], :3]).sum(axis=1)
    w = np.sign((bary * t[faces[tri], 3:]).sum(axis=1))
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    T -= np.sum(T * N, axis=1, keepdims=True) * N
    T /= np.linalg.norm(T, axis=1, keepdims=True)
    B = np.cross(N, T) * w
    view = doc["bufferViews"][doc["images"][1]["bufferView"]]
    image = iio.imread(blob[view["byteOffset"]:view["byteOffset"] + view["byteLength"]])
    ts = image[..., :3][inside] / 255.0 * 2 - 1
    rebuilt = ts[:, :1] * T + ts[:, 1:2] * B + ts[:, 2:] * N
    err = np.linalg.norm(rebuilt - normals[inside], axis=1)
    assert np.percentile(err, 99) < 0.02, np.percentile(err, [50, 99, 100])


def test_a_name_is_limited_in_bytes_as_the_file_system_is():
    """File systems allow 255 bytes a name, and the temporary file beside an output adds
    14: a name of 200 characters could be 400 bytes (é) and failed at the write, after the
    work (exit 1). Now refused before any work, naming the bytes."""
    from jaxskin.io import InputError
    from jaxskin.outputs import MAX_NAME_BYTES, check_name

    assert MAX_NAME_BYTES + len(".") + len(".abcdefgh.tmp") <= 255
    assert check_name("é" * 120) == "é" * 120  # 240 bytes
    for name, size in (("é" * 121, 242), ("日本" * 41, 246), ("a" * 199 + "😀" * 1, 203)):
        if size > MAX_NAME_BYTES:
            with pytest.raises(InputError, match=f"is {size} bytes in UTF-8, over the 240"):
                check_name(name)
        else:
            assert check_name(name) == name


@pytest.mark.parametrize("channels", [3, 4])
def test_a_16_bit_colour_png_is_read_at_full_depth(tmp_path, channels):
    """Pillow (under imageio) reads 16-bit RGB(A) PNGs as 8 bits, the low byte dropped:
    `render --format png16` given back as a fit-image target lost its precision (RMS 0.0012,
    the 8-bit floor). Read at 16 bits now, by jaxskin's own writer and by pypng's."""
    import png

    from jaxskin.maps import png16_bytes, read_image

    rng = np.random.default_rng(3)
    samples = rng.integers(0, 65536, (9, 13, channels)).astype(np.uint16)
    samples[0, 0, :3] = 257  # 1/255 in 16 bits: 8 bits would give 257 // 256 = 1 → 1/255
    samples[0, 1, :3] = 255  # below one 8-bit level: 0 in 8 bits
    ours = tmp_path / "ours.png"
    ours.write_bytes(png16_bytes(samples))
    theirs = tmp_path / "theirs.png"
    with theirs.open("wb") as fh:
        png.Writer(13, 9, bitdepth=16, greyscale=False, alpha=channels == 4).write(
            fh, samples.reshape(9, -1).tolist())
    for path in (ours, theirs):
        rgb, alpha = read_image(path)
        np.testing.assert_array_equal(rgb, samples[..., :3] / 65535.0)
        if channels == 4:
            np.testing.assert_array_equal(alpha, samples[..., 3] / 65535.0)
        else:
            assert alpha is None
        assert rgb[0, 1, 0] == 255 / 65535


def test_a_long_scene_name_gives_way_to_the_digest_or_names_the_scene(tmp_path, capsys):
    """A scene named with 170 letters rendered with two -D values: the name plus the -D part
    was over 200 characters and the error named neither the file nor its key. Now the -D
    part becomes its digest (the file is written); 199 letters leave no room at all: one
    line naming the scene file and 'name', exit 2, nothing written."""
    from jaxskin.cli import main

    small = ["-D", "camera.size=32", "-D", "texture.size=32"]
    (tmp_path / "mid.toml").write_text(f'name = "{"a" * 170}"\n')
    assert main(["render", str(tmp_path / "mid.toml"), "-o", str(tmp_path / "o"), *small]) == 0
    written = [p.name for p in (tmp_path / "o").iterdir()]
    assert len(written) == 1 and written[0].startswith("a" * 170 + "_D-"), written
    assert len(written[0]) == 170 + len("_D-") + 12 + len(".png")
    (tmp_path / "long.toml").write_text(f'name = "{"a" * 199}"\n')
    assert main(["render", str(tmp_path / "long.toml"), "-o", str(tmp_path / "p"), *small]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"jaxskin: error: {tmp_path / 'long.toml'}: key 'name': the scene's "
                          "name is 199 characters; with what this run adds"), err
    assert len(err.splitlines()) == 1 and not (tmp_path / "p").exists()


def test_a_name_given_with_D_is_the_whole_name(tmp_path, capsys):
    """`-D name=espresso_look` with other -D values must not write
    espresso_look_D-13e6f4956f9c.png: a name given with -D is the file's name, nothing
    added; the same name for two scenes of one command is refused before any work, naming
    -D (not a bare "give the inputs distinct names")."""
    from jaxskin.cli import main

    small = ["-D", "camera.size=32", "-D", "texture.size=32"]
    assert main(["render", "hand", "-o", str(tmp_path / "o"), "-D", "name=espresso_look",
                 "-D", "material.melanin=0.3", *small]) == 0
    assert sorted(p.name for p in (tmp_path / "o").iterdir()) == ["espresso_look.png"]
    assert main(["render", "hand", "-o", str(tmp_path / "o"), *small]) == 0  # no -D name
    assert "hand_camera.size-32_texture.size-32.png" in {p.name for p in
                                                        (tmp_path / "o").iterdir()}
    assert main(["render", "hand", "foot", "-o", str(tmp_path / "q"), "-D", "name=x",
                 *small]) == 2
    assert ("jaxskin: error: -D name=x: gives all 2 scenes of the command one name"
            in capsys.readouterr().err)
    assert not (tmp_path / "q").exists()
    # a key given twice names the file by the value used, the last (both were in the name)
    assert main(["render", "hand", "-o", str(tmp_path / "r"), "-D", "material.melanin=0.1",
                 "-D", "material.melanin=0.9", *small]) == 0
    assert [p.name for p in (tmp_path / "r").iterdir()] == [
        "hand_material.melanin-0.9_camera.size-32_texture.size-32.png"]


def test_renders_are_tagged_srgb_and_data_maps_are_not(tmp_path):
    """A render's PNG holds sRGB-encoded values and says so: it has an
    sRGB chunk (perceptual intent) and PNG 1.2's gAMA of 1/2.2 right after IHDR, 8 and 16
    bits, with the same samples; a height or thickness map (data, not colour) has neither."""
    import io

    from PIL import Image

    image = np.random.default_rng(0).uniform(0, 1, (5, 7, 3))
    for bits in (8, 16):
        data = maps.image_bytes(image, bits)
        assert data[33:41] == b"\x00\x00\x00\x01sRGB" and data[46:54] == b"\x00\x00\x00\x04gAMA"
        info = Image.open(io.BytesIO(data)).info
        assert info["srgb"] == 0 and info["gamma"] == pytest.approx(0.45455)
        samples = iio.imread(data) if bits == 8 else maps.png16_colour(data)
        assert np.array_equal(samples, maps.quantize(image, bits))
    maps.write_height(np.full((4, 4), 0.5), tmp_path / "h.png")
    maps.write_grey16(np.full((4, 4), 0.5), tmp_path / "t.png")
    for name in ("h.png", "t.png"):
        data = (tmp_path / name).read_bytes()
        assert b"sRGB" not in data and b"gAMA" not in data


def test_an_output_folder_named_like_a_file(tmp_path):
    """`calibrate -o fit.json` must not make a folder 'fit.json': refused where the command
    names the files; `fit.json/` (a trailing slash), an existing folder of that name, and
    fit-brdf's folder (its -o is the file) are taken."""
    from jaxskin.io import InputError
    from jaxskin.outputs import check_folder

    with pytest.raises(InputError, match=r"got a file name \('fit.json'; .*'fit.json/' to make"):
        check_folder(tmp_path / "fit.json")
    assert check_folder(f"{tmp_path / 'fit.json'}/") == tmp_path / "fit.json"
    assert check_folder(tmp_path / "v1.json", named_files=False) == tmp_path / "v1.json"
    (tmp_path / "renders.png").mkdir()
    assert check_folder(tmp_path / "renders.png") == tmp_path / "renders.png"


def test_a_name_from_a_file_name_that_is_not_utf8_is_kept():
    """A Latin-1 file name `café.toml` reads (on POSIX) with a surrogate for é; surrogates
    are not control characters, and refusing them would refuse a scene that renders.
    Invisible characters that make two names look alike are refused."""
    from jaxskin.io import InputError
    from jaxskin.outputs import check_name

    assert check_name("caf\udce9") == "caf\udce9"
    assert check_name("نامه\u200cها") == "نامه\u200cها"  # a zero-width non-joiner: Persian
    for hidden in ("a\u200bb", "a\ufeffb", "a\u2060b"):
        with pytest.raises(InputError, match="contains a control character"):
            check_name(hidden)


def test_png_bytes_are_imageios_bytes():
    """`maps.png_bytes` calls Pillow directly (twice as fast): the file is imageio's, byte
    for byte, for grey, RGB, RGBA and 16-bit grey (a render's PNG did not change with it)."""
    import imageio.v3 as iio

    from jaxskin import maps

    rng = np.random.default_rng(0)
    for shape, dtype in [((7, 9), np.uint8), ((64, 48, 3), np.uint8), ((33, 20, 4), np.uint8),
                         ((9, 7), np.uint16)]:  # 16-bit grey: the height map
        image = rng.integers(0, np.iinfo(dtype).max + 1, shape).astype(dtype)
        assert maps.png_bytes(image) == iio.imwrite("<bytes>", image, extension=".png"), shape
