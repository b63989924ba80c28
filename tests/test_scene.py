"""Scene files: every bad value gets a one-line error naming the key; -D overrides; the
static/param split; stages a scene does not use are not run; the render command."""

import re
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

from jaxskin import texture, wrinkles
from jaxskin.io import InputError
from jaxskin.scene import load_scene

GOOD = """
[mesh]
file = "foot"
projection = "planar"
[texture]
size = 64
[wrinkles]
k_scale = 1.0
k_bump = 0.5
[[fields.edit]]
at = [0.0, 0.0, 0.04]
d1 = [0.6, 0.8, 0.0]
d2 = [-0.6, 0.8, 0.0]
"""

BAD = [
    ("unknown key", GOOD.replace("k_bump", "k_bumb"), "wrinkles.k_bumb", "did you mean 'wrinkles.k_bump'"),
    ("unknown table", GOOD + "\n[camra]\nfov = 3\n", "camra.fov", "unknown table [camra]; did you mean 'camera.fov'?"),
    ("unknown table, no such key", GOOD + "\n[lights]\nx = 1\n", "lights.x", "unknown table [lights]; did you mean [light]?"),
    ("out of range", GOOD.replace("k_scale = 1.0", "k_scale = 3.0"), "wrinkles.k_scale", "[0.5, 2]"),
    ("wrong type", GOOD.replace("size = 64", 'size = "big"'), "texture.size", "expected int"),
    ("bool for int", GOOD.replace("size = 64", "size = true"), "texture.size", "expected int"),
    ("bad choice", GOOD.replace('"planar"', '"spherical"'), "mesh.projection", "planar, cylindrical, uv"),
    ("edit without at", GOOD.replace("at = [0.0, 0.0, 0.04]", ""), "fields.edit[0]", "exactly one of 'at'"),
    ("edit too long", GOOD.replace("d1 = [0.6, 0.8, 0.0]", "d1 = [3.0, 0.0, 0.0]"), "fields.edit[0].d1", "[0, 2]"),
    ("edit bad key", GOOD.replace("d2 =", "d3 = [0,0,0]\nd2 ="), "fields.edit[0].d3", "did you mean 'd2'"),
    ("edit weight", GOOD + "weight = 11\n", "fields.edit[0].weight", "[0, 10]"),
    ("material model", GOOD + "[material]\nmodel = \"phong\"\n", "material.model", "blinn, lafortune"),
    ("melanin", GOOD + "[material]\nmelanin = 1.5\n", "material.melanin", "[0, 1]"),
    ("shininess", GOOD + "[material]\nshininess = -1\n", "material.shininess", "[0, 10000]"),
    ("brdf file", GOOD + "[material]\nbrdf = \"nope.json\"\n", "material.brdf", "fit-brdf"),
    ("light zero", GOOD + "[light]\ndirection = [0, 0, 0]\n", "light.direction", "must not be zero"),
    ("light shape", GOOD + "[light]\ndirection = [0, 1]\n", "light.direction", "three finite numbers"),
    ("camera", GOOD + "[camera]\nprojection = \"fisheye\"\n", "camera.projection", "orthographic, perspective"),
    ("supersample", GOOD + "[camera]\nsupersample = 8\n", "camera.supersample", "[1, 4]"),
    ("view mode", GOOD + "[view]\nmode = \"wire\"\n", "view.mode", "wrinkles, overview, height"),
    ("camera typo", GOOD + "[camera]\nsise = 8\n", "camera.sise", "did you mean 'camera.size'"),
    ("zoom below 1", GOOD + "[camera]\nzoom = 0.5\n", "camera.zoom", "[1, 64]"),
    ("zoom nan", GOOD + "[camera]\nzoom = nan\n", "camera.zoom", "finite number"),
    ("center outside", GOOD + "[camera]\ncenter = [0.6, 0.0]\n", "camera.center", "[-0.5, 0.5]"),
    ("center three", GOOD + "[camera]\ncenter = [0, 0, 0]\n", "camera.center", "two finite numbers"),
    ("center text", GOOD + "[camera]\ncenter = \"lips\"\n", "camera.center", "two finite numbers"),
    ("center inf", GOOD + "[camera]\ncenter = [inf, 0]\n", "camera.center", "two finite numbers"),
]


@pytest.mark.parametrize("what, text, key, words", BAD, ids=[b[0] for b in BAD])
def test_bad_scene_files(tmp_path, what, text, key, words):
    path = tmp_path / "scene.toml"
    path.write_text(text)
    with pytest.raises(InputError) as info:
        load_scene(path)
    message = str(info.value)
    assert "\n" not in message and message.startswith(f"{path}: key '{key}'"), message
    assert words in message, message


def test_invalid_toml_and_unknown_scene(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text('name = "x"\n[mesh\n')
    with pytest.raises(InputError) as info:  # the line where every error puts it
        load_scene(path)
    assert str(info.value) == (f"{path}:2: not valid TOML: Expected ']' at the end of a table "
                               "declaration (column 6)")
    with pytest.raises(InputError, match="built-in scenes: hand, foot, arm"):
        load_scene("elbow")


@pytest.mark.parametrize("name, content, words", [
    ("rouge.json", b'{"name": "rouge", "S": [1.0]}\n', "a JSON file, not a TOML scene file: a "
     "calibrated material (what calibrate writes) is named by a scene's [[layer]] material"),
    ("fit", b'\xef\xbb\xbf  {"lobes": []}', "a JSON file, not a TOML scene file"),
    ("m.csv", b"wavelength_nm,R_inf\n400,0.3\n", "a table, not a TOML scene file: "
     "measurements are calibrated with 'jaxskin calibrate'"),
    ("blush.png", b"\x89PNG\r\n\x1a\n\x00\x00", "an image, not a TOML scene file"),
    ("a.jpg", b"\xff\xd8\xff\xe0\x00\x10JFIF", "an image, not a TOML scene file"),
])
def test_another_kind_of_file_given_as_a_scene_is_named(tmp_path, name, content, words):
    """`jaxskin render rouge.json` (a material calibrate wrote) is not "not valid TOML:
    Invalid statement": a JSON file, a table or an image is named as what it is."""
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(InputError) as info:
        load_scene(path)
    assert str(info.value).startswith(f"{path}: {words}"), str(info.value)


def test_overrides_are_checked_like_the_file(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(GOOD)
    sc = load_scene(path, ["wrinkles.k_bump=0.8", "texture.size=32", "mesh.projection=uv"])
    assert sc.values["wrinkles.k_bump"] == 0.8 and sc.config.texture.size == 32
    assert sc.config.texture.projection == "uv"
    with pytest.raises(InputError, match="^override wrinkles.k_bump=7: key 'wrinkles.k_bump'"):
        load_scene(path, ["wrinkles.k_bump=7"])
    with pytest.raises(InputError, match="did you mean 'texture.size'"):
        load_scene(path, ["texture.sise=32"])
    # the command line names its own flag: API errors do not say "-D", which Python users
    # never type
    with pytest.raises(InputError, match="^-D wrinkles.k_bump=7: key 'wrinkles.k_bump'"):
        load_scene(path, ["wrinkles.k_bump=7"], flag="-D")
    with pytest.raises(InputError, match="^expected override key=value, got 'k_bump'"):
        load_scene(path, ["k_bump"])
    # not "unknown key; did you mean 'fields.edit'?" for fields.edit itself
    for item, table in (("fields.edit=[]", "[[fields.edit]]"), ("layer=1", "[[layer]]")):
        with pytest.raises(InputError, match=re.escape(f"{table} tables are written in a scene "
                                                       "file; they cannot be set as one value")):
            load_scene(path, [item])
    # a string was read character by character: "expected -D key=value, got 't'"
    assert load_scene(path, iter([])).config.texture.size == 64  # any iterable of strings
    assert load_scene(path, (o for o in ["texture.size=32"])).config.texture.size == 32
    for overrides in ("texture.size=32", {"texture.size": 32}, [("texture.size", 32)]):
        with pytest.raises(TypeError, match="^overrides: expected a list of 'key=value' "
                                            "strings, got "):
            load_scene(path, overrides)


def test_a_camera_size_alone_keeps_the_frames_aspect(tmp_path):
    """`-D camera.size=N` on a scene whose file sets camera.height (the arm: 1024 x 320)
    scales the height with the width, as the user asking for a smaller image expects (it
    once gave a 64 x 320 strip with the arm a sliver across it); an explicit height wins;
    a square scene stays square; a height over the key's maximum is an error naming it."""
    arm = load_scene("arm", ["camera.size=64"])
    assert (arm.config.image, arm.config.image_height) == (64, 20)
    assert load_scene("arm", ["camera.size=100"]).config.image_height == 31  # 31.25
    assert load_scene("arm", ["camera.size=64", "camera.height=64"]).config.image_height == 64
    assert load_scene("arm", ["camera.size=64", "camera.height=0"]).config.image_height == 0
    assert load_scene("arm", ["camera.height=100"]).config.image == 1024
    assert load_scene("hand", ["camera.size=64"]).config.image_height == 0
    tall = tmp_path / "tall.toml"
    tall.write_text(GOOD + "[camera]\nsize = 320\nheight = 1024\n")
    assert load_scene(tall, ["camera.size=160"]).config.image_height == 512
    with pytest.raises(InputError, match=r"^override camera.size=4096: key 'camera.size': expected "
                                         r"at most 2560 .* give camera.height too"):
        load_scene(tall, ["camera.size=4096"])


def test_static_config_and_params_split(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(GOOD)
    a, b = load_scene(path), load_scene(path, ["wrinkles.k_bump=0.9"])
    assert a.config == b.config and hash(a.config) == hash(b.config)  # same jit cache key
    assert {"wrinkles.k_bump", "wrinkles.k_noise", "material.melanin", "light.direction"} <= set(
        a.params)
    assert not set(a.params) & {"mesh.file", "texture.size", "camera.size", "view.mode"}
    assert float(b.params["wrinkles.k_bump"]) == pytest.approx(0.9)
    assert load_scene(path, ["wrinkles.k_scale=1.5"]).config != a.config


def test_a_scene_without_wrinkles_runs_no_furrow_program(tmp_path, monkeypatch):
    path = tmp_path / "s.toml"
    path.write_text(GOOD)
    calls = []
    original = wrinkles.height_field

    def counting(*args, **kwargs):
        calls.append(1)
        return original(*args, **kwargs)

    monkeypatch.setattr(wrinkles, "height_field", counting)
    texture.furrows.cache_clear()
    plain = load_scene(path, ["wrinkles.enabled=false"])
    maps = texture.texture_maps(plain.config, plain.params)
    assert calls == []
    np.testing.assert_array_equal(maps["normals"], texture.setup(plain.config.texture).normals)
    wrinkled = load_scene(path)
    texture.texture_maps(wrinkled.config, wrinkled.params)
    assert calls == [1]
    texture.furrows.cache_clear()


def test_render_maps_command(tmp_path):
    """The maps beside the render, at the texture's size (the camera's kept small: it is not
    what is checked; in this process, as the command line's `main`)."""
    from jaxskin.cli import main

    out = tmp_path / "out"
    assert main(["render", "foot", "-o", str(out), "--maps", "-D", "texture.size=96",
                 "-D", "camera.size=32"]) == 0
    base = out / "foot_texture.size-96_camera.size-32"  # -D overrides name the outputs
    height = iio.imread(f"{base}_height.png")
    assert height.dtype == np.uint16 and height.shape == (96, 96) and height.min() < 60000
    assert iio.imread(f"{base}_normal.png").shape == (96, 96, 3)
    assert iio.imread(f"{base}_field.png").ndim == 3


def test_render_bad_scene_exit_2_and_nothing_written(tmp_path, capsys):
    from jaxskin.cli import main

    bad = tmp_path / "bad.toml"
    bad.write_text(GOOD.replace("k_scale = 1.0", "k_scale = 9.0"))
    out = tmp_path / "out"
    assert main(["render", "foot", str(bad), "-o", str(out), "--maps"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "wrinkles.k_scale" in err and "Traceback" not in err
    assert not out.exists()


def test_paths_from_the_file_and_from_the_command_line(tmp_path, monkeypatch):
    from jaxskin.formats import write_lafortune
    from jaxskin.shading import lafortune

    (tmp_path / "scenes").mkdir()
    (tmp_path / "fits").mkdir()
    write_lafortune(lafortune.skin(), tmp_path / "scenes" / "mine.json")
    write_lafortune(lafortune.skin(), tmp_path / "fits" / "other.json")
    scene = tmp_path / "scenes" / "s.toml"
    scene.write_text(GOOD + '\n[material]\nmodel = "lafortune"\nbrdf = "mine.json"\n')
    assert load_scene(scene).values["material.brdf"] == str(tmp_path / "scenes" / "mine.json")
    monkeypatch.chdir(tmp_path)
    over = load_scene(scene, ["material.brdf=fits/other.json"])
    assert over.values["material.brdf"] == str(tmp_path / "fits" / "other.json")
    assert over.params["material.lafortune"].n.shape == (3, 3)


def test_an_override_the_scene_does_not_use_is_found():
    """`jaxskin render` warns (after its checks, before any work) about a -D value that
    changes nothing: `-D skin.subject=50` on the Blinn hand would render the default hand
    under a new name, without a word."""
    from jaxskin.checks import unused_overrides

    def unused(name, *items):
        overrides = [*items, "texture.size=32"]
        return unused_overrides(load_scene(name, overrides), overrides)

    assert unused("hand", "skin.subject=50", "material.melanin=0.5") == ["skin.subject=50"]
    assert unused("face", "skin.subject=50", "material.melanin=0.5") == ["material.melanin=0.5"]
    assert unused("hand", "material.melanin=0.2", "name=x") == []  # the scene's own value
    assert unused("makeup", "layer.blush.thickness_mm=0.02", "camera.size=64") == []
    brdf = str(Path(__file__).resolve().parents[1] / "data" / "brdf" / "skin_samples.csv")
    assert unused("hand", f"material.brdf={brdf}") == [f"material.brdf={brdf}"]
    # camera.fov on an orthographic scene gives the same image, so is warned of, and
    # wrinkles.method=sequential counts as used on a CPU, where auto picks it
    assert unused("hand", "camera.fov=60") == ["camera.fov=60"]
    assert unused("hand", "camera.fov=60", "camera.projection=perspective") == []
    assert unused("hand", "wrinkles.method=sequential") == []
    assert unused("hand", "wrinkles.method=parallel") == []


def test_an_unused_override_names_the_key_the_scene_reads():
    """The warning for a `-D` key of the other skin model names the one the scene reads
    (`-D skin.melanin=0.3` on the Blinn hand); a key with no such twin names none."""
    from jaxskin.checks import read_instead

    small = ["texture.size=32"]
    assert read_instead(load_scene("hand", small), "skin.melanin=0.3") == "material.melanin"
    assert read_instead(load_scene("face", small), "material.melanin=0.3") == "skin.melanin"
    assert read_instead(load_scene("hand", small), "skin.subject=50") is None
    assert read_instead(load_scene("hand", small), "camera.fov=60") is None
    # with the command's other -D values: Lafortune reads neither melanin
    lafortune = [*small, "material.model=lafortune", "skin.melanin=0.3"]
    assert read_instead(load_scene("hand", lafortune), "skin.melanin=0.3", lafortune) is None


def test_a_layers_material_is_set_with_D(tmp_path, monkeypatch):
    """`-D layer.NAME.material=...` swaps a layer's product for a batch render: a shipped
    name, or a file taken from the working directory (as every path given with -D), checked
    like the file's own before any work."""
    import shutil

    from jaxskin.cosmetics import data_dir

    def material(sc, name):
        return next(layer.material for layer in sc.config.spectral.layers if layer.name == name)

    shipped = data_dir() / "materials"
    base = load_scene("makeup", ["camera.size=64"])
    assert material(base, "foundation") == str(shipped / "foundation_light.json")
    dark = load_scene("makeup", ["layer.foundation.material=foundation_dark"])
    assert material(dark, "foundation") == str(shipped / "foundation_dark.json")
    assert material(dark, "blush") == material(base, "blush")
    (tmp_path / "mine").mkdir()
    shutil.copy(shipped / "lipstick_red.json", tmp_path / "mine" / "red.json")
    monkeypatch.chdir(tmp_path)
    mine = load_scene("makeup", ["layer.blush.material=mine/red.json",
                                 "layer.blush.thickness_mm=0.02"])
    assert material(mine, "blush") == str(tmp_path / "mine" / "red.json")
    assert mine.params["layer.blush.thickness_mm"] == 0.02
    last = load_scene("makeup", ["layer.blush.material=foundation_dark",
                                 "layer.blush.material=mine/red.json"])
    assert material(last, "blush") == str(tmp_path / "mine" / "red.json")
    bad = [("layer.blush.material=nope", "override layer.blush.material=nope: key "
            "'layer.blush.material': no material file"),
           ("layer.blush.material=foundation_biege", "did you mean 'foundation_beige'"),
           ("layer.blush.material=1", "override layer.blush.material=1: key 'layer.blush.material': "
            "expected a material"),
           ("layer.cheek.material=blush_rose", "scene makeup.toml has no layer named 'cheek'"),
           ("layer.lips.thickness_mm=0.01", "no layer named 'lips' \\(did you mean 'lipstick'"),
           ("layer.blush.colour=red", "one of thickness_mm, .*, material")]
    for item, words in bad:
        with pytest.raises(InputError, match=words):
            load_scene("makeup", [item])
    (tmp_path / "table.csv").write_text("wavelength_nm,value\n400,1\n")
    with pytest.raises(InputError, match="table.csv: a CSV file, .*jaxskin calibrate"):
        load_scene("makeup", ["layer.blush.material=table.csv"])


def test_a_scene_saved_with_a_byte_order_mark_and_crlf_reads_as_without(tmp_path):
    """Windows editors save UTF-8 with a byte-order mark and CRLF line ends: read alike
    (the mark was 'Invalid statement (at line 1, column 1)'); UTF-16 and binary files get
    a message that says what the file is."""
    plain, marked = tmp_path / "plain.toml", tmp_path / "marked.toml"
    plain.write_text(GOOD, encoding="utf-8")
    marked.write_bytes(b"\xef\xbb\xbf" + GOOD.replace("\n", "\r\n").encode("utf-8"))
    a, b = load_scene(plain), load_scene(marked)
    assert a.config == b.config and a.values == {**b.values, "name": a.values["name"]}
    (tmp_path / "wide.toml").write_bytes(GOOD.encode("utf-16"))
    with pytest.raises(InputError, match="wide.toml: is UTF-16 text; a TOML file is UTF-8"):
        load_scene(tmp_path / "wide.toml")
    (tmp_path / "image.toml").write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00")
    with pytest.raises(InputError, match=r"image.toml: an image, not a TOML scene file"):
        load_scene(tmp_path / "image.toml")
    (tmp_path / "binary.toml").write_bytes(b"\x80\x81\x00\x00")
    with pytest.raises(InputError, match=r"binary.toml: is not UTF-8 text \(byte 0\)"):
        load_scene(tmp_path / "binary.toml")


@pytest.mark.parametrize("region", [
    "[[layer.ellipse]]\ncenter = [5.0, 5.0]\nradii = [0.1, 0.1]\n",
    "[[layer.ellipse]]\ncenter = [256.0, 300.0]\nradii = [40.0, 30.0]\n",
    "[[layer.ellipse]]\ncenter = [-0.35, 0.5]\nradii = [0.1, 0.2]\nfeather = 0.1\n",
    "[[layer.polygon]]\npoints = [[1.2, 0.1], [1.5, 0.1], [1.3, 0.4]]\n",
], ids=["far", "pixels", "left", "polygon"])
def test_a_region_wholly_off_the_texture_is_refused(tmp_path, region):
    """An ellipse centred at uv (5, 5) (or in pixels) painted nothing, without a word."""
    text = ('name = "m"\n[mesh]\nfile = "face"\n[texture]\nsize = 32\n[material]\n'
            'model = "spectral"\n[[layer]]\nname = "blush"\nmaterial = "blush_rose"\n' + region)
    (tmp_path / "s.toml").write_text(text)
    with pytest.raises(InputError, match=r"layer\.blush\.(ellipse|polygon)\[0\]'?: lies "
                       "wholly outside the texture"):
        load_scene(tmp_path / "s.toml")
    near = text.replace("5.0, 5.0", "1.05, 0.5").replace("-0.35", "-0.25").replace(
        "256.0, 300.0", "0.5, 0.5").replace("40.0, 30.0", "0.1, 0.1").replace("1.2", "0.95")
    (tmp_path / "t.toml").write_text(near)
    load_scene(tmp_path / "t.toml")  # reaching into the texture: kept



def test_a_skin_map_whose_scalar_is_0_is_found(tmp_path, capsys):
    """`skin.melanin_image` scales `skin.melanin`, 0 by default: the face rendered with a map
    and without one were the same to the byte, and nothing said so. Now one warning naming
    both keys; with `skin.melanin` set, or without a map, there is none."""
    import imageio.v3 as iio

    from jaxskin.checks import idle_maps
    from jaxskin.cli import main

    iio.imwrite(tmp_path / "m.png", np.tile(np.linspace(0, 255, 32, dtype=np.uint8), (32, 1)))
    small = ["texture.size=32", "camera.size=32", "sss.enabled=false"]
    img = f"skin.melanin_image={tmp_path / 'm.png'}"
    assert idle_maps(load_scene("face", [*small, img])) == [
        "skin.melanin_image scales skin.melanin, which is 0 in scene 'face': the map changes "
        "nothing (set skin.melanin above 0, e.g. to 1)"]
    assert idle_maps(load_scene("face", [*small, img, "skin.melanin=1"])) == []
    assert idle_maps(load_scene("face", small)) == []
    args = [a for o in [*small, img] for a in ("-D", o)]
    assert main(["render", "face", "-o", str(tmp_path / "out"), *args]) == 0
    assert "warning: skin.melanin_image scales skin.melanin, which is 0" in \
        capsys.readouterr().err


def test_a_skin_map_the_model_does_not_read_is_named_and_never_overwritten(tmp_path, capsys):
    """A Blinn scene with `skin.melanin_image = "n.png"`, rendered into its own folder,
    must not replace the user's n.png with the render (the map is no input of a model that
    does not read it). A warning names the idle key, and the map is an input the outputs
    may not overwrite."""
    import imageio.v3 as iio

    from jaxskin.checks import idle_maps
    from jaxskin.cli import main

    grey = np.full((16, 16), 128, np.uint8)
    iio.imwrite(tmp_path / "n.png", grey)
    (tmp_path / "n.toml").write_text('name = "n"\n[mesh]\nfile = "hand"\n[skin]\n'
                                     'melanin_image = "n.png"\n')
    assert idle_maps(load_scene(tmp_path / "n.toml")) == [
        "skin.melanin_image changes nothing in scene 'n': its material model (blinn) reads "
        "no skin map"]
    # A map of the other spectral skin: left out of the configuration, named (the
    # biophysical face renders the same to the byte with skin.melanin_image, and the
    # spectral face with skin.melanin_fraction_image).
    bio = load_scene("face", ["material.model=biophysical", "skin.melanin_fraction=0.3",
                              f"skin.melanin_image={tmp_path / 'n.png'}"])
    assert bio.config == load_scene("face", ["material.model=biophysical",
                                             "skin.melanin_fraction=0.3"]).config
    assert idle_maps(bio) == [
        "skin.melanin_image changes nothing in scene 'face': its material model "
        "(biophysical, biophysical skin) reads skin.melanin_fraction_image, "
        "skin.haemoglobin_image and skin.brightness_image instead"]
    nist = load_scene("face", [f"skin.melanin_fraction_image={tmp_path / 'n.png'}"])
    assert idle_maps(nist) == [
        "skin.melanin_fraction_image changes nothing in scene 'face': its material model "
        "(spectral, nist skin) reads skin.melanin_image instead"]
    args = ["-D", "texture.size=32", "-D", "camera.size=32", "-D",
            f"skin.melanin_fraction_image={tmp_path / 'n.png'}"]
    assert main(["render", "face", "-o", str(tmp_path / "out"), *args]) == 0
    err = [line for line in capsys.readouterr().err.splitlines() if "warning" in line]
    assert err == ["jaxskin: warning: skin.melanin_fraction_image changes nothing in scene "
                   "'face': its material model (spectral, nist skin) reads skin.melanin_image "
                   "instead"], err  # once: not also as a -D that changes nothing
    assert main(["render", str(tmp_path / "n.toml"), "-o", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert f"n.png: the output {tmp_path / 'n.png'} would overwrite this input" in err, err
    np.testing.assert_array_equal(iio.imread(tmp_path / "n.png"), grey)


def test_a_check_failing_on_a_D_value_names_the_D_item(tmp_path, capsys):
    """`-D mesh.projection=uv` on the hand (no texture coordinates) was blamed on
    data/scenes/hand.toml, which does not set it; now the -D item is named. An error about
    a key no -D set still names the scene file."""
    from jaxskin.cli import main

    assert main(["render", "hand", "-o", str(tmp_path), "-D", "mesh.projection=uv"]) == 2
    assert capsys.readouterr().err.strip() == (
        "jaxskin: error: -D mesh.projection=uv: key 'mesh.projection': mesh 'hand' has no "
        "texture coordinates; use planar or cylindrical projection")
    (tmp_path / "uv.toml").write_text('[mesh]\nfile = "hand"\nprojection = "uv"\n')
    assert main(["render", str(tmp_path / "uv.toml"), "-o", str(tmp_path / "o"),
                 "-D", "camera.size=32"]) == 2
    assert capsys.readouterr().err.startswith(f"jaxskin: error: {tmp_path / 'uv.toml'}: key "
                                              "'mesh.projection'")


def test_a_biophysical_material_over_an_explicit_measured_skin_is_refused(tmp_path):
    """`material.model = "biophysical"` renders the biophysical skin; an explicit
    `skin.model = "nist"` beside it would be silently ignored. It is an
    error naming where the nist skin came from; left at its default, nothing is said."""
    with pytest.raises(InputError, match=r"^override skin.model=nist: key 'skin.model': .*"
                                         r"material.model = \"spectral\""):
        load_scene("face", ["material.model=biophysical", "skin.model=nist"])
    scene = tmp_path / "s.toml"
    scene.write_text('[material]\nmodel = "biophysical"\n[skin]\nmodel = "nist"\n')
    with pytest.raises(InputError, match=rf"^{scene}: key 'skin.model'"):
        load_scene(scene)
    assert load_scene("face", ["material.model=biophysical"]).skin_model == "biophysical"
    assert load_scene(scene, ["skin.model=biophysical"]).skin_model == "biophysical"
    assert load_scene(scene, ["material.model=spectral"]).skin_model == "nist"


def test_the_modules_example_scene_shows_the_defaults(tmp_path):
    """`render --help` sends readers to `python -m pydoc jaxskin.scene` for the defaults; its
    example must not say `k_scale = 1.1` where the default is 1.0. Every key of the
    example that has a default shows it, and the example is a valid scene: its edit must
    not give both `at` and `vertex`, which the parser refuses."""
    import tomllib

    from jaxskin import scene

    example = tomllib.loads(scene.__doc__.split("```toml")[1].split("```")[0])
    parsed = scene.parse_scene(example, tmp_path / "example.toml")
    assert parsed.name == "hand" and len(parsed.edits) == 1

    def flat(d, prefix=""):
        for k, v in d.items():
            if isinstance(v, dict):
                yield from flat(v, f"{prefix}{k}.")
            else:
                yield prefix + k, v

    shown = dict(flat(example))
    checked = [k for k in shown if k in scene.SCHEMA and scene.SCHEMA[k].default is not None]
    assert len(checked) >= 29
    for key in checked:
        default = scene.SCHEMA[key].default
        assert shown[key] == (list(default) if isinstance(default, tuple) else default), key


def test_the_modules_cosmetics_example_is_a_valid_scene(tmp_path):
    """The second example (the cosmetics model's keys) must not give a layer both `image`
    and regions, which the parser refuses, or copied into a file it fails. With the model
    it names and its images made, it parses, and its layer is the regions'."""
    import tomllib

    from jaxskin import scene

    example = tomllib.loads(scene.__doc__.split("```toml")[2].split("```")[0])
    example["material"] = {"model": "spectral"}
    for name in ("melanin.png", "m.png", "h.png", "b.png", "c.png", "s.png"):
        iio.imwrite(tmp_path / name, np.full((8, 8), 128, np.uint8))
    parsed = scene.parse_scene(example, tmp_path / "example.toml")
    (layer,) = example["layer"]
    assert "image" not in layer and layer["ellipse"] and layer["polygon"]
    assert parsed.values["layer.blush.thickness_mm"] == 0.01


def test_a_cosmetic_layer_millimetres_thick_is_warned():
    """`-D layer.foundation.thickness_mm=10` meant as 10 µm is accepted (the key allows up
    to 10 mm) and renders an opaque mask: it is warned of."""
    from jaxskin.checks import thick_layers

    assert thick_layers(load_scene("makeup")) == []
    assert thick_layers(load_scene("makeup", ["layer.foundation.thickness_mm=0.9"])) == []
    assert thick_layers(load_scene("makeup", ["layer.foundation.thickness_mm=10"])) == [
        "layer.foundation.thickness_mm = 10 mm: cosmetic films are 0.1 µm to 1 mm thick "
        "(10 µm is 0.01 mm); at this thickness most products are opaque"]


def test_an_edit_with_null_for_the_missing_key_is_read():
    """The editor's /api/state lists each edit with `"vertex": null` (or `"at": null`);
    posting that list back must not be "give exactly one of 'at' or 'vertex'". JSON's
    null is no value: the edit reads as without that key."""
    from jaxskin.scene import parse_scene

    edits = [{"at": [0.0, 0.4, 0.1], "vertex": None, "d1": [1.0, 0.0, 0.0],
              "d2": [0.0, 1.0, 0.0]},
             {"at": None, "vertex": 5, "d1": [1.0, 0.0, 0.0], "d2": [0.0, 1.0, 0.0],
              "weight": None}]
    sc = parse_scene({"mesh": {"file": "hand"}, "fields": {"edit": edits}}, "s.toml")
    assert [(e.at, e.vertex, e.weight) for e in sc.edits] == [((0.0, 0.4, 0.1), None, 1.0),
                                                             (None, 5, 1.0)]
    with pytest.raises(InputError, match="give exactly one of 'at'"):
        parse_scene({"fields": {"edit": [{"at": None, "vertex": None, "d1": [1, 0, 0],
                                          "d2": [0, 1, 0]}]}}, "s.toml")


def test_a_list_given_to_D_without_brackets_is_the_list():
    """`-D camera.rotate=0,60,0` is not refused as the string '0,60,0': numbers with
    commas are the list; words with commas stay a string, a vector key's message shows the
    form."""
    from jaxskin.io import InputError
    from jaxskin.scene import load_scene, parse_override

    assert parse_override("camera.rotate=0,60,0") == ("camera.rotate", [0, 60, 0])
    assert parse_override("camera.center = -0.1, 0.25") == ("camera.center", [-0.1, 0.25])
    assert parse_override("name=a,b") == ("name", "a,b")
    assert parse_override("material.melanin=0,5") == ("material.melanin", "0,5")  # a scalar
    with pytest.raises(InputError, match=r"got '0,5' \(a decimal comma\? write 0\.5\)"):
        load_scene("hand", ["material.melanin=0,5"])
    assert parse_override("skin.melanin=0.3") == ("skin.melanin", 0.3)
    turned = load_scene("face", ["camera.rotate=0,60,0"]).values["camera.rotate"]
    assert list(turned) == [0, 60, 0]
    with pytest.raises(InputError, match=r"expected three finite numbers \(\[x, y, z\]\), got "
                                         r"'sideways'"):
        load_scene("face", ["camera.rotate=sideways"])


@pytest.mark.parametrize("text, value", [(".5", 0.5), ("5.", 5.0), ("-.5e1", -5.0),
                                         ("+.25", 0.25), ("0,5", "0,5"), ("abc", "abc")])
def test_a_number_without_a_digit_before_or_after_the_point_is_a_number(text, value):
    """`-D material.melanin=.5` is not "expected a finite number, got '.5'" (TOML wants
    digits on both sides of the point): such numbers are read as numbers."""
    from jaxskin.scene import parse_override

    assert parse_override(f"material.melanin={text}") == ("material.melanin", value)
    if isinstance(value, float) and 0 <= value <= 1:
        assert load_scene("hand", [f"material.melanin={text}"]).values[
            "material.melanin"] == value


@pytest.mark.parametrize("item, value", [
    ("camera.rotate=.5,0,0", [0.5, 0, 0]), ("camera.rotate=[0, 60., 0]", [0, 60.0, 0]),
    ("layer.blush.thickness_mm=.01", 0.01), ("texture.size=512.", 512.0),
    # text keys keep what was typed (name=5. stays '5.', not 5.0)
    ("name=5.", "5."), ("material.brdf=.5.json", ".5.json"),
    ("layer.blush.material=.5.json", ".5.json"),
])
def test_a_point_alone_is_completed_in_numbers_only(item, value):
    from jaxskin.scene import parse_override

    assert parse_override(item)[1] == value


def test_a_scene_with_a_txt_ending_and_a_toml_error_gets_the_toml_error(tmp_path):
    """A `.txt` scene with a syntax error is not called "a table" for its commas: only a
    first row of cells without `=` is a table."""
    path = tmp_path / "s.txt"
    path.write_text("# my scene\n[camera]\nrotate = [0, 60, 0\n")
    with pytest.raises(InputError, match=r"s.txt: not valid TOML: Unclosed array"):
        load_scene(path)
