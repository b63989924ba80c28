"""Skin maps from a texture (`jaxskin.skin_maps`, `jaxskin.skin_texture`, `jaxskin
skin-maps`): the colour formulas against colour-science, the inversion of textures made
from known maps, a real photo (ΔE and the mask), the new scene keys (render, gradients),
bad inputs."""

import colour
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from PIL import Image

from jaxskin import biophysical, formats, maps, render, skin_maps, skin_texels, spectral
from jaxskin.cli import main
from jaxskin.io import data_dir
from jaxskin.scene import load_scene

PHOTO = data_dir() / "textures" / "astronaut_face.png"
GRID = spectral.Grid(step=10)


def test_colour_formulas_match_colour_science():
    """sRGB decoding/encoding and CIELAB against colour-science's own (IEC 61966-2-1,
    CIE 15), on random values: within 1e-12."""
    v = np.random.default_rng(0).uniform(0, 1, (200, 3))
    assert np.allclose(skin_maps.decode_srgb(v), colour.cctf_decoding(v, "sRGB"), atol=1e-12)
    assert np.allclose(skin_maps.encode_srgb(v), colour.cctf_encoding(v, "sRGB"), atol=1e-12)
    white = np.array([0.95047, 1.0, 1.08883])
    xyz = v * white
    xyz[:5] *= 1e-3  # the linear part below (6/29)³
    ref = colour.XYZ_to_Lab(xyz, colour.XYZ_to_xy(white))
    assert np.allclose(skin_maps._lab_np(xyz, white), ref, atol=1e-9)
    with jax.enable_x64(True):
        assert np.allclose(np.asarray(skin_maps.lab(jnp.asarray(xyz), white)), ref, atol=1e-9)


def _known_maps(h=24, w=24, bits=8):
    """Smooth melanin, haemoglobin and brightness maps, and the texture the renderer's
    colour pipeline (`spectral.to_rgb`, `render.encode_srgb`) makes of them in float64,
    rounded to `bits`."""
    y, x = np.mgrid[:h, :w] / (max(h, w) - 1)
    truth = {"melanin": 0.01 * 30.0 ** x, "haemoglobin": 0.003 * 20.0 ** y,
             "brightness": 0.6 + 0.8 * (x + y) / 2}
    with jax.enable_x64(True):
        c = biophysical.chromophores(GRID.wavelengths, formats.haemoglobin_table())
        d = biophysical.DEFAULT
        R = biophysical.reflectance(c, biophysical.Skin(
            truth["melanin"], d.eumelanin, truth["haemoglobin"], d.oxygenation,
            d.epidermis_mm, d.scattering)) * truth["brightness"][..., None]
        rgb = np.asarray(render.encode_srgb(spectral.to_rgb(R, GRID)))
    return truth, maps.quantize(rgb, bits) / (2.0 ** bits - 1)


@pytest.mark.parametrize("bits, median, p95", [(16, 0.002, 0.02), (8, 0.06, 0.25)])
def test_known_maps_are_recovered_within_the_colour_noise(bits, median, p95):
    """A 24² texture made from smooth known maps (melanin 0.01-0.3, haemoglobin 0.003-0.06,
    brightness 0.6-1.4), rounded to 16 or 8 bits: every texel is skin, the reproduction
    within ΔE2000 0.05 at the median (measured 0.000) and 0.5 at most (0.11), and each
    map's relative error within what the rounding allows. Measured, median and 95th
    percentile: 16 bits: melanin 0.007 % and 0.13 %, haemoglobin 0.02 % and 0.7 %,
    brightness 0.003 % and 0.013 %; 8 bits: 1.3 % and 5.9 %, 4.3 % and 15 %, 0.7 % and
    1.9 %: the blood fraction is the least determined (half an 8-bit step moves it most
    where it is small)."""
    truth, texture = _known_maps(bits=bits)
    inv = skin_maps.invert(texture)
    assert inv.skin.all()
    assert np.median(inv.de) < 0.05 and inv.de.max() < 0.5
    for name, value in truth.items():
        rel = np.abs(getattr(inv, name) / value - 1)
        print(f"{bits} bits, {name}: median {np.median(rel):.4f}, "
              f"p95 {np.percentile(rel, 95):.4f}")
        assert np.median(rel) < median and np.percentile(rel, 95) < p95, name
    assert np.abs(inv.rgb - texture).max() < 3 / 255


@pytest.fixture(scope="module")
def photo():
    """The astronaut crop (data/README.md) and its inversion."""
    rgb, _ = maps.read_image(PHOTO)
    return rgb, skin_maps.invert(rgb)


def test_a_real_photo_is_reproduced_over_its_skin(photo):
    """The astronaut's face (a NASA photo, 180 × 200, not made here): over the skin texels
    ΔE2000 median ≤ 1.0 and 95th percentile ≤ 3.0 (the aim; measured 0.00 and 1.70), with
    the skin a third of the picture (measured 36 %: face, neck, some of the pinkish
    background)."""
    _, inv = photo
    de = inv.de[inv.skin]
    print(f"skin {inv.skin.mean():.3f}, median {np.median(de):.3f}, "
          f"p95 {np.percentile(de, 95):.3f}")
    assert np.median(de) <= 1.0 and np.percentile(de, 95) <= 3.0
    assert 0.25 < inv.skin.mean() < 0.5


def test_the_mask_keeps_the_face_and_drops_hair_and_eyes(photo):
    """On the photo: the cheeks and forehead are skin (over 95 %); the hair above the
    forehead and the irises are mostly not (under 20 %). (The teeth are about half in:
    their pale cream is a colour the skin model makes.)"""
    _, inv = photo
    skin = inv.skin
    for name, (rows, cols) in {"left cheek": ((120, 140), (60, 80)),
                               "right cheek": ((120, 140), (125, 145)),
                               "forehead": ((85, 95), (85, 115))}.items():
        assert skin[slice(*rows), slice(*cols)].mean() > 0.95, name
    for name, (rows, cols) in {"hair": ((25, 45), (60, 140)),
                               "left iris": ((99, 104), (81, 86)),
                               "right iris": ((101, 106), (125, 130))}.items():
        assert skin[slice(*rows), slice(*cols)].mean() < 0.2, name


def test_clearly_non_skin_colours_are_masked():
    """Patches of blue, green, grey-blue, purple and pure white next to skin patches (from
    known maps): the skin patches are in the mask, the others out of it, whole."""
    _, skin = _known_maps(8, 8)
    patches = [skin, np.broadcast_to([0.2, 0.3, 0.8], (8, 8, 3)),
               np.broadcast_to([0.2, 0.65, 0.25], (8, 8, 3)), skin[::-1],
               np.broadcast_to([0.45, 0.5, 0.6], (8, 8, 3)),
               np.broadcast_to([0.55, 0.2, 0.6], (8, 8, 3)), np.ones((8, 8, 3))]
    texture = np.concatenate(patches, axis=1)
    inv = skin_maps.invert(texture)
    expect = [True, False, False, True, False, False, False]
    for k, want in enumerate(expect):
        got = inv.skin[:, 8 * k:8 * k + 8]
        assert (got.all() if want else not got.any()), (k, inv.de[:, 8 * k:8 * k + 8].min())


def test_the_command_writes_maps_and_a_snippet(tmp_path, capsys):
    """`jaxskin skin-maps` on the photo writes the 16-bit maps and mask, the reproduction
    (8-bit RGB, the texture's size), the snippet and the report."""
    out = tmp_path / "out"
    assert main(["skin-maps", str(PHOTO), "-o", str(out)]) == 0
    said = capsys.readouterr().out
    assert "skin" in said and "95th percentile" in said
    stem = PHOTO.stem
    for suffix in ("_melanin", "_haemoglobin", "_brightness", "_skin_mask"):
        with Image.open(out / f"{stem}{suffix}.png") as im:
            assert im.size == (180, 200) and im.mode.startswith("I;16"), suffix
    with Image.open(out / f"{stem}_reproduced.png") as im:
        assert im.size == (180, 200) and im.mode == "RGB"
    assert (out / f"{stem}_skin_maps.png").stat().st_size > 10_000
    assert f'mask_image = "{stem}_skin_mask.png"' in (out / f"{stem}_skin.toml").read_text()


@pytest.mark.parametrize("texel, skin", [((0.78, 0.6, 0.5), True), ((0.2, 0.3, 0.8), False)],
                         ids=["skin", "blue"])
def test_a_flat_render_of_the_snippet_shows_the_texture_colour(tmp_path, texel, skin):
    """A texture of one colour through `jaxskin skin-maps`, its snippet given a UV mesh and
    rendered flat (ambient light only, no highlight, no SSS, no furrows): a light skin's
    colour is skin, rendered from the maps; a blue is not skin, rendered from its own
    colour (`skin.colour_image`, `skin.mask_image`). Either way the picture shows the
    texture's colour (ΔE2000 under 1): the maps mean the colour under D65."""
    src = tmp_path / "one.png"
    Image.fromarray(np.uint8(np.round(np.broadcast_to(texel, (16, 16, 3)) * 255))).save(src)
    assert main(["skin-maps", str(src), "-o", str(tmp_path), "--no-report"]) == 0
    assert maps.read_grey(tmp_path / "one_skin_mask.png").all() == skin
    assert (not maps.read_grey(tmp_path / "one_skin_mask.png").any()) == (not skin)
    snippet = (tmp_path / "one_skin.toml").read_text().replace('# file = "scan.obj"',
                                                                'file = "face"')
    (tmp_path / "one_skin.toml").write_text(
        snippet + "[light]\nambient = 1.0\nintensity = 0.0\n[sss]\nenabled = false\n"
        "[wrinkles]\nenabled = false\n[camera]\nsize = 32\nsupersample = 1\n"
        "[texture]\nsize = 32\n")
    sc = load_scene(tmp_path / "one_skin.toml", ["skin.specular=0", "mesh.unit_mm=10"])
    img = np.asarray(render.render(sc.config, sc.params))[..., :3]
    middle = img[14:18, 14:18].reshape(-1, 3)
    lab = colour.XYZ_to_Lab(colour.sRGB_to_XYZ(middle))
    de = colour.delta_E(lab, colour.XYZ_to_Lab(colour.sRGB_to_XYZ(texel)), method="CIE 2000")
    assert de.max() < 1.0, de


@pytest.mark.parametrize("texel, skin", [((0.78, 0.6, 0.5), True), ((0.2, 0.3, 0.8), False)],
                         ids=["skin", "blue"])
def test_cosmetics_lie_on_the_skin_only(tmp_path, texel, skin):
    """The same flat scenes as above under a thick lipstick over the whole face: on a texel
    the mask calls skin the lipstick shows (ΔE2000 from the texture over 10); on one it
    does not (the blue: an eye, hair), the texture's own colour stays as it was (under 1)."""
    src = tmp_path / "one.png"
    Image.fromarray(np.uint8(np.round(np.broadcast_to(texel, (16, 16, 3)) * 255))).save(src)
    assert main(["skin-maps", str(src), "-o", str(tmp_path), "--no-report"]) == 0
    snippet = (tmp_path / "one_skin.toml").read_text().replace('# file = "scan.obj"',
                                                                'file = "face"')
    (tmp_path / "one_skin.toml").write_text(
        snippet + "[light]\nambient = 1.0\nintensity = 0.0\n[sss]\nenabled = false\n"
        "[wrinkles]\nenabled = false\n[camera]\nsize = 32\nsupersample = 1\n"
        "[texture]\nsize = 32\n[[layer]]\nname = \"lips\"\nmaterial = \"lipstick_red\"\n"
        "thickness_mm = 0.05\nspecular = 0.0\n")
    sc = load_scene(tmp_path / "one_skin.toml", ["skin.specular=0", "mesh.unit_mm=10"])
    img = np.asarray(render.render(sc.config, sc.params))[..., :3]
    lab = colour.XYZ_to_Lab(colour.sRGB_to_XYZ(img[14:18, 14:18].reshape(-1, 3)))
    de = colour.delta_E(lab, colour.XYZ_to_Lab(colour.sRGB_to_XYZ(texel)), method="CIE 2000")
    assert (de.min() > 10.0) if skin else (de.max() < 1.0), de


def test_own_colour_is_a_stage_only_scenes_with_the_keys_have(tmp_path):
    """Without skin.colour_image and skin.mask_image the prepared arrays have no own
    colour (nothing traced for it); one of the two alone is an error naming the other;
    `upsample`'s spectra give back their colour (colour-science's ΔE2000 under 0.01 for
    colours a [0, 1] spectrum can have; the clipped green within 2) and lie in [0, 1]."""
    from jaxskin.io import InputError

    ov = ["texture.size=16", "camera.size=16", "material.model=biophysical",
          "wrinkles.enabled=false", "sss.enabled=false"]
    assert "own_R" not in render.prepare(load_scene("face", ov).config).arrays
    Image.fromarray(np.full((4, 4, 3), 100, np.uint8)).save(tmp_path / "c.png")
    maps.write_grey16(np.zeros((4, 4)), tmp_path / "m.png")
    with pytest.raises(InputError, match="needs skin.mask_image too"):
        load_scene("face", [*ov, f"skin.colour_image={tmp_path / 'c.png'}"])
    both = load_scene("face", [*ov, f"skin.colour_image={tmp_path / 'c.png'}",
                               f"skin.mask_image={tmp_path / 'm.png'}"])
    arrays = render.prepare(both.config).arrays
    assert arrays["own_R"].shape == (len(arrays["texels"]), len(both.config.spectral.grid))
    c = np.array([[0.2, 0.3, 0.8], [0.45, 0.5, 0.6], [0.1, 0.08, 0.05], [0.55, 0.2, 0.6],
                  [0.2, 0.65, 0.25]])
    R = skin_maps.upsample(c, GRID)
    assert R.min() >= 0 and R.max() <= 1
    back = colour.XYZ_to_Lab(colour.sRGB_to_XYZ(skin_maps.encode_srgb(R @ GRID.rgb_matrix)))
    de = colour.delta_E(back, colour.XYZ_to_Lab(colour.sRGB_to_XYZ(c)), method="CIE 2000")
    assert (de[:4] < 0.01).all() and de[4] < 2.0, de


def test_brightness_keys_render_and_differentiate(tmp_path):
    """skin.brightness scales the biophysical skin's reflectance (× its map, loaded from
    skin.brightness_image like the other skin maps); the NIST skin's params and a scene
    without the image leave it out (no map array prepared); gradients of the skin
    reflectance with respect to the scalar and the map check in float64, forward and
    reverse."""
    from jax.test_util import check_grads

    ov = ["texture.size=16", "camera.size=16", "wrinkles.enabled=false", "sss.enabled=false"]
    assert "skin.brightness" not in load_scene("makeup", ov).params
    sc = load_scene("face", [*ov, "material.model=biophysical"])
    assert "skin.brightness" in sc.params
    arrays = render.prepare(sc.config).arrays
    assert skin_texels.map_cover("skin.brightness_map") not in arrays
    half = np.full((16, 16), 0.5)
    maps.write_grey16(half, tmp_path / "b.png")
    with_map = load_scene("face", [*ov, "material.model=biophysical",
                                   f"skin.brightness_image={tmp_path / 'b.png'}"])
    a_map = render.prepare(with_map.config).arrays
    sp = sc.config.spectral
    texels = arrays["texels"]
    R0 = skin_texels.skin_reflectance(sp, sc.params, arrays, texels)
    R1 = skin_texels.skin_reflectance(with_map.config.spectral, with_map.params, a_map, texels)
    assert np.allclose(np.asarray(R1), 0.5 * np.asarray(R0), rtol=1e-4)  # 16-bit 0.5
    with jax.enable_x64(True):
        arrays64 = {**arrays, "chromophores": jnp.asarray(arrays["chromophores"],
                                                          jnp.float64)}
        base = {k: jnp.asarray(v, jnp.float64) for k, v in sc.params.items()}

        @jax.jit
        def f(b, m):
            return skin_texels.skin_reflectance(sp, {**base, "skin.brightness": b,
                                                "skin.brightness_map": m}, arrays64, texels)

        for b in (0.7, 2.0):  # ordinary, and the range's top
            check_grads(f, (jnp.float64(b), jnp.asarray(half + 0.3)), order=1,
                        modes=("fwd", "rev"), atol=1e-6, rtol=1e-6)


def _grey(tmp):
    p = tmp / "grey.png"
    Image.fromarray(np.full((8, 8), 128, np.uint8)).save(p)
    return p


def _text(tmp):
    p = tmp / "notes.png"
    p.write_text("not an image")
    return p


@pytest.mark.parametrize("make, extra, message", [
    (_grey, [], "expected a colour (RGB) texture"),
    (_text, [], "cannot read as an image"),
    (lambda tmp: tmp / "none.png", [], "no such file"),
    (lambda tmp: PHOTO, ["--fix", "melanin=0.1"], "fitted per texel"),
    (lambda tmp: PHOTO, ["--fix", "eumelanin=2"], "expected a number in [0, 1]"),
    (lambda tmp: PHOTO, ["--threshold", "0"], "expected a finite number >= 0.1"),
], ids=["grey", "not-an-image", "missing", "fix-fitted", "fix-range", "threshold"])
def test_bad_inputs_one_line_exit_2_nothing_written(tmp_path, capsys, make, extra, message):
    """Each bad input: exit 2, one line naming what was expected, no output folder made."""
    out = tmp_path / "out"
    with pytest.raises(SystemExit) if extra[:1] == ["--threshold"] else _nothing():
        code = main(["skin-maps", str(make(tmp_path)), "-o", str(out), *extra])
        assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
    assert not out.exists()


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def test_16_bit_and_alpha_textures_are_handled_and_said(tmp_path, capsys):
    """A 16-bit RGBA texture: fitted at full depth, its transparent texels out of the mask,
    each said in one note line."""
    _, texture = _known_maps(8, 8)
    rgba = np.concatenate([texture, np.ones((8, 8, 1))], axis=-1)
    rgba[:, :4, 3] = 0.0
    rgba[..., :3] += 1 / 65535  # samples between the 8-bit steps
    src = tmp_path / "deep.png"
    src.write_bytes(maps.png16_bytes(np.round(rgba * 65535).astype(np.uint16)))
    assert main(["skin-maps", str(src), "-o", str(tmp_path / "out"), "--no-report"]) == 0
    err = capsys.readouterr().err
    assert "16 bits per channel: read at full depth" in err
    assert "its transparent texels (50%) are not skin" in err
    mask = maps.read_grey(tmp_path / "out" / "deep_skin_mask.png")
    assert not mask[:, :4].any() and mask[:, 4:].all()


def test_skin_texture_key_renders_the_texture_and_caches_it(tmp_path, monkeypatch, capsys):
    """`skin.texture` on a biophysical scene: `jaxskin render` inverts the texture once,
    keeps the maps in OUT/skin_maps_<hash>/, and a flat render shows the texture's colour
    (ΔE2000 under 1; a blue, not skin, from its own colour); the next run reads the maps
    back instead of inverting again. With a skin map image as well it is an error; on
    another skin it is named as changing nothing."""
    from jaxskin import skin_texture
    from jaxskin.io import InputError

    texture = np.zeros((16, 16, 3))
    texture[:, :8] = (0.78, 0.6, 0.5)
    texture[:, 8:] = (0.2, 0.3, 0.8)
    Image.fromarray(np.uint8(np.round(texture * 255))).save(tmp_path / "scan.png")
    (tmp_path / "s.toml").write_text(
        'name = "s"\n[mesh]\nfile = "face"\nprojection = "uv"\nunit_mm = 10.0\n'
        '[material]\nmodel = "biophysical"\n[skin]\ntexture = "scan.png"\nspecular = 0.0\n'
        "[light]\nambient = 1.0\nintensity = 0.0\n[sss]\nenabled = false\n"
        "[wrinkles]\nenabled = false\n[camera]\nsize = 32\nsupersample = 1\n"
        "[texture]\nsize = 32\n")
    out = tmp_path / "out"
    skin_texture._MEMO.clear()
    assert main(["render", str(tmp_path / "s.toml"), "-o", str(out)]) == 0
    cached = list(out.glob("skin_maps_*/*/texture_melanin.png"))
    assert len(cached) == 1
    sc = load_scene(tmp_path / "s.toml")
    img = np.asarray(render.render(sc.config, sc.params))[..., :3]
    arrays = render.prepare(sc.config).arrays
    assert skin_texels.map_cover("skin.brightness_map") in arrays and "own_R" in arrays
    for cols, texel in ((slice(9, 12), texture[0, 0]), (slice(20, 23), texture[0, -1])):
        px = img[14:18, cols].reshape(-1, 3)  # the face's UVs: u left to right
        de = colour.delta_E(colour.XYZ_to_Lab(colour.sRGB_to_XYZ(px)),
                            colour.XYZ_to_Lab(colour.sRGB_to_XYZ(texel)), method="CIE 2000")
        assert de.max() < 1.0, (texel, de)

    def no_inversion(*a, **k):
        raise AssertionError("inverted again")

    skin_texture._MEMO.clear()
    render.prepare.cache_clear()  # else the arrays prepared above are reused, not the files
    monkeypatch.setattr(skin_texture, "invert_texture", no_inversion)
    assert main(["render", str(tmp_path / "s.toml"), "-o", str(out)]) == 0
    maps.write_grey16(np.ones((4, 4)), tmp_path / "h.png")
    with pytest.raises(InputError, match="give one of the two"):
        load_scene(tmp_path / "s.toml", [f"skin.haemoglobin_image={tmp_path / 'h.png'}"])
    from jaxskin.checks import idle_maps

    assert idle_maps(load_scene(tmp_path / "s.toml", ["material.model=spectral"])) == [
        "skin.texture changes nothing in scene 's': only the biophysical skin reads it "
        '(material.model = "biophysical")']
