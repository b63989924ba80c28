"""Blinn and Lafortune shade only the view's samples on the mesh (`jaxskin.samples`)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import assert_same_bytes
from jax.test_util import check_grads

from jaxskin import render
from jaxskin.samples import STEP, sample_list, to_pixels
from jaxskin.scene import load_scene, scene_at_width
from jaxskin.view import downsample


def _view(seed=0, k=2, H=5, W=7):
    rng = np.random.default_rng(seed)
    shaded = rng.random((k * H, k * W)) < 0.4
    tex = rng.random((k * H, k * W, 2)).astype(np.float32) * 10
    return shaded, tex


def test_the_list_holds_the_shaded_samples_and_pads_to_a_bucket():
    shaded, tex = _view()
    t = sample_list(tex, shaded, 2)
    M = int(shaded.sum())
    assert t["list_tex"].shape == (-(-M // STEP) * STEP, 2)
    assert t["list_on"].sum() == M and not t["list_on"][M:].any()
    assert np.array_equal(t["list_index"][:M], np.flatnonzero(shaded))
    assert np.array_equal(t["list_tex"][:M], tex.reshape(-1, 2)[np.flatnonzero(shaded)])
    # each pixel lists its own samples only: its 2 x 2 block, in the block's row order
    rows, cols = np.nonzero(shaded)
    for i, (r, c) in enumerate(zip(rows, cols, strict=True)):
        assert t["covered_pixel"][t["list_pixel"][i]] == (r // 2) * 7 + c // 2
        assert t["pixel_list"][t["list_pixel"][i], (r % 2) * 2 + c % 2] == i
        assert t["pixel_covered"][(r // 2) * 7 + c // 2] == t["list_pixel"][i]
    with pytest.raises(ValueError, match="cannot hold"):
        sample_list(tex, shaded, 2, length=M - 1)
    # one sample a pixel: the covered pixels' rows are the list's, in its order (the
    # renderer then takes the list as the rows, `render._render`)
    for length in (None, shaded.size):
        t = sample_list(tex, shaded, 1, length)
        assert t["pixel_list"].shape == (t["list_on"].size, 1)
        assert np.array_equal(t["pixel_list"][:M, 0], np.arange(M))
        assert np.all(t["pixel_list"][M:, 0] == t["list_on"].size)
        assert np.array_equal(t["covered_pixel"][:M], t["list_index"][:M])


@pytest.mark.parametrize("k", [1, 2, 3])
def test_the_pixels_are_the_mean_of_the_scattered_samples(k):
    """Against `view.downsample` of the samples put back in their places (0 elsewhere)."""
    shaded, tex = _view(1, k)
    t = sample_list(tex, shaded, k)
    values = np.random.default_rng(2).normal(size=(t["list_on"].size, 3)).astype(np.float32)
    values[~t["list_on"]] = 0.0
    full = np.zeros((shaded.size, 3), np.float32)
    full[np.flatnonzero(shaded)] = values[t["list_on"]]
    expected = np.asarray(downsample(full.reshape(*shaded.shape, 3), k))
    got = np.asarray(to_pixels(values, t, (5, 7)))
    np.testing.assert_allclose(got, expected, rtol=0, atol=2e-7)


def test_the_pixel_mean_is_gradient_checked(x64):
    shaded, tex = _view(3)
    t = sample_list(tex, shaded, 2)
    values = jnp.asarray(np.random.default_rng(4).normal(size=(t["list_on"].size, 3)))

    @jax.jit  # one program each way, not op by op
    def f(v):
        return to_pixels(v, t, (5, 7)) ** 2

    check_grads(f, (values,), order=1, modes=("fwd", "rev"))
    # the padding reads no pixel: its gradient is 0
    g = jax.grad(lambda v: jnp.sum(f(v)))(values)
    assert np.all(np.asarray(g)[~t["list_on"]] == 0)


def test_the_hand_shades_only_the_samples_it_shows():
    """Leave out what the scene does not need: the default hand covers about a quarter of
    its view, and the program shades a list of about that length, not every sample."""
    sc = scene_at_width("hand", 128)
    a = render.prepare(sc.config).arrays
    total = a["view_shaded"].size
    seen = int(np.asarray(a["view_shaded"]).sum())
    assert int(a["list_on"].sum()) == seen
    assert seen <= a["list_tex"].shape[0] < seen + STEP
    assert a["list_tex"].shape[0] < 0.4 * total
    # what the program computes per sample has the list's length (not the view's)
    hlo = jax.jit(lambda p, a: render.render_prepared(sc.config, p, a)).lower(
        sc.params, a).as_text()
    n = a["list_tex"].shape[0]
    assert f"tensor<{n}x3xf32>" in hlo
    assert f"tensor<{a['view_shaded'].shape[0]}x{a['view_shaded'].shape[1]}x3xf32>" not in hlo


HAND = """\
name = "tiny_hand"
[mesh]
file = "hand"
[texture]
size = {texture}
[camera]
size = {camera}
supersample = {k}
"""


@pytest.mark.parametrize("texture,camera,k,corners", [(64, 64, 2, False), (128, 24, 1, True)])
def test_the_editor_turns_a_blinn_hand_without_a_new_program(tmp_path, texture, camera, k,
                                                             corners):
    """The render's list is as long as the samples on the mesh, which a turn changes; the
    editor lists every sample instead, so a turn or a zoom compiles nothing new, and each
    image is still `jaxskin render`'s: with the whole texture's bump, and with the bump at
    the samples' corners (a texture with more texels than the view's samples' corners)."""
    pytest.importorskip("aiohttp", reason="the editor needs aiohttp (the edit extra)")
    from jaxskin.editor import Session

    (tmp_path / "tiny_hand.toml").write_text(HAND.format(texture=texture, camera=camera, k=k))
    (tmp_path / "out").mkdir()
    s = Session(str(tmp_path / "tiny_hand.toml"), tmp_path / "out")
    s.render()
    assert ("corner_texels" in s.arrays(s.scene.config)) == corners
    lengths = set()
    for changes in ({"camera.rotate": [10.0, 25.0, 0.0]}, {"camera.zoom": 2.0},
                    {"camera.rotate": [-40.0, 60.0, 0.0], "camera.zoom": 1.0}):
        compiled = render._render._cache_size()
        s.set(changes)
        image = s.render()
        assert render._render._cache_size() == compiled, changes
        lengths.add(int(render.prepare(s.scene.config).arrays["list_on"].sum()))
        expected = np.asarray(render.render(s.scene.config, s.scene.params))
        assert_same_bytes(np.round(np.clip(image, 0, 1) * 255),
                          np.round(np.clip(expected, 0, 1) * 255), changes)
    assert len(lengths) > 1  # the samples on the mesh differ: the editor's one program
    # covers every view (a CLI render's list is as long as its count, rounded up)


@pytest.mark.parametrize("wrap_x", [False, True])
def test_sampling_at_known_corners_is_sampling_the_padded_image(wrap_x, x64):
    """`view.sample_corners` (the corners' texels found once, through the padding) against
    `view.sample_padded` (the whole image padded, then sampled): equal values, and the
    gradient (fwd, and rev through the transpose table) checked."""
    from jaxskin.samples import list_corners
    from jaxskin.view import pad_index, sample_corners, sample_padded, transpose_table

    rng = np.random.default_rng(5)
    mask = np.zeros((12, 16), bool)
    mask[2:10, 1:15] = True
    mask[4:6, 6:9] = False
    pad = pad_index(mask, wrap_x)
    shaded = rng.random((6, 8)) < 0.7
    tex = (rng.random((6, 8, 2)) * [16, 12]).astype(np.float32)
    t = sample_list(tex, shaded, 2)
    corners = list_corners(t["list_tex"], t["list_on"], pad, mask.shape, wrap_x)
    table = transpose_table(t["list_tex"], t["list_on"], pad, mask.shape, wrap_x)
    table = [table[k] for k in ("view_rows", "view_weights", "view_dest")]
    image = jnp.asarray(rng.normal(size=(12, 16, 3)))
    ours = sample_corners(image, corners, t["list_tex"], t["list_on"], table)
    theirs = sample_padded(image, pad, t["list_tex"], t["list_on"], wrap_x)
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-15)
    check_grads(jax.jit(lambda im: sample_corners(im, corners, t["list_tex"], t["list_on"],
                                                  table) ** 2),
                (image,), order=1, modes=("fwd", "rev"))


@pytest.mark.parametrize("name", ["hand", "arm"])
def test_the_bump_at_the_samples_corners_is_the_whole_maps_there(name):
    """Blinn and Lafortune compute the bump at the texels their samples read only
    (`texture.bumped_at`): against the whole texture's bump map (`texture.bumped`) sampled
    at the same samples. The hand is planar (eq. 4.10), the arm cylindrical (the general
    form, s wrapping at the seam); noise on, so that the masked heights count too."""
    from jaxskin import texture
    from jaxskin.vectors import unit
    from jaxskin.view import blend_corners, sample_corners

    sc = scene_at_width(name, 96, ["texture.size=128", "camera.supersample=1",
                                   "wrinkles.k_noise=0.4", "camera.rotate=-90,0,0"])
    a, p = render.prepare(sc.config).arrays, sc.params
    s = texture.setup(sc.config.texture)
    assert ("corner_grad_s" in a) == (name == "arm")
    whole = texture.bumped(a["normals"], a["mask"], a["h0"], a["noise"], p, s.frame,
                           s.tmap.wrap_x)["normals"]
    expected = sample_corners(whole, a["list_corners"], a["list_tex"], a["list_on"])
    got = blend_corners(texture.bumped_at(a["h0"], a, p), a["list_tex"], a["list_on"])
    np.testing.assert_allclose(got, expected, rtol=0, atol=2e-7)
    on = np.asarray(a["list_on"])
    assert on.sum() > 150 and np.all(np.abs(np.linalg.norm(unit(got)[on], axis=-1) - 1) < 1e-6)
    if name == "arm":  # the view reads texels in both the seam's first and last columns
        W = s.mask.shape[1]
        cols = np.asarray(a["list_corners"])[:, on] % W
        assert cols.min() == 0 and cols.max() == W - 1


@pytest.mark.parametrize("k_bump", [0.5, 1e6])
def test_the_bump_at_the_samples_corners_is_gradient_checked(k_bump, x64):
    """With respect to the height map, k_bump and k_noise, in float64, at an ordinary and
    a huge k_bump (the normals then lie along the height's gradient)."""
    from jaxskin import texture
    from jaxskin.view import blend_corners

    sc = scene_at_width("arm", 16, ["texture.size=64", "camera.supersample=1",
                                    "wrinkles.k_noise=0.4"])
    a = render.prepare(sc.config).arrays
    inputs = {k: jnp.asarray(v, jnp.float64) if np.asarray(v).dtype == np.float32 else v
              for k, v in a.items() if k.startswith("corner_")}
    h0 = jnp.asarray(a["h0"], jnp.float64)

    def f(h, kb, kn):
        n = texture.bumped_at(h, inputs, {"wrinkles.k_bump": kb, "wrinkles.k_noise": kn})
        return blend_corners(n, jnp.asarray(a["list_tex"], jnp.float64), a["list_on"])

    args = (h0, jnp.float64(k_bump), jnp.float64(0.4))
    check_grads(f, args, order=1, modes=("fwd", "rev"), eps=1e-6 if k_bump > 1 else 1e-4)
    value, grads = jax.value_and_grad(lambda *x: jnp.sum(f(*x) ** 3), argnums=(0, 1, 2))(*args)
    assert np.isfinite(value) and all(np.all(np.isfinite(g)) for g in grads)


def test_the_bump_is_made_where_it_is_less_work():
    """The corners' bump where the listed samples' corners are fewer than the texels (the
    like-for-like hand of benchmarks/bench_mitsuba.py: a 1024² texture, 512² samples), the
    whole texture's where they are not (the default hand: a 512² texture, 1024² samples)."""
    for over, corners in ((["camera.size=128", "texture.size=256", "camera.supersample=1"],
                           True), (["camera.size=128", "texture.size=128"], False)):
        sc = load_scene("hand", over)
        a = render.prepare(sc.config).arrays
        assert ("corner_texels" in a) == corners, over
        assert (4 * a["list_on"].size < a["mask"].size) == corners


def test_a_blinn_program_computes_no_texture_sized_normal_map():
    """Leave out what the scene does not need: the hand's bump is computed at its samples'
    corner texels, not over its whole texture (the texture is larger than the view)."""
    sc = scene_at_width("hand", 64, ["texture.size=256"])
    a = render.prepare(sc.config).arrays
    assert "corner_texels" in a
    hlo = jax.jit(lambda p, a: render.render_prepared(sc.config, p, a)).lower(
        sc.params, a).compile().as_text()
    assert "256,256,3" not in hlo and "65536,3" not in hlo
    assert f"4,{a['list_tex'].shape[0]}" in hlo  # the corners' normals


def test_the_covered_pixels_give_every_output_as_the_whole_image_did():
    """The list's pixels are averaged, exposed and encoded as a list, then placed: each
    output against the same steps done on the whole image, by hand (`view.downsample` of
    the samples put back in their places; alpha the share of a pixel's samples that see
    the mesh), on a hand at 2 × 2 samples a pixel, so that its outline is partly covered."""
    from jaxskin.view import downsample

    sc = scene_at_width("hand", 40, ["texture.size=64", "camera.supersample=2",
                                     "camera.exposure=0.5"])
    a, p = render.prepare(sc.config).arrays, sc.params
    linear = np.asarray(render.render(sc.config, p, "linear_rgba"), np.float64)
    rgba = np.asarray(render.render(sc.config, p, "rgba"), np.float64)
    display = np.asarray(render.render(sc.config, p), np.float64)
    alpha = np.asarray(downsample(np.asarray(a["view_mask"], np.float32)[..., None], 2))
    partly = (alpha[..., 0] > 0) & (alpha[..., 0] < 1)
    assert partly.sum() > 20
    np.testing.assert_array_equal(linear[..., 3:], alpha)
    np.testing.assert_array_equal(rgba[..., 3:], alpha)

    def encode(x):  # IEC 61966-2-1, float64
        return np.where(x > 0.0031308, 1.055 * np.maximum(x, 0.0031308) ** (1 / 2.4) - 0.055,
                        12.92 * x)

    np.testing.assert_allclose(display, encode(linear[..., :3]), rtol=0, atol=2e-6)
    covered = alpha[..., 0] > 0
    straight = np.where(covered[..., None], linear[..., :3] / np.where(covered, alpha[..., 0],
                                                                       1)[..., None], 0)
    np.testing.assert_allclose(rgba[..., :3], encode(straight), rtol=0, atol=2e-6)
    assert np.all(display[~covered] == 0) and np.all(rgba[~covered] == 0)
    # exposure on the list: half a stop brighter than at 0 (linear light)
    base = np.asarray(render.render(sc.config, {**p, "camera.exposure": 0.0}, "linear_rgba"))
    np.testing.assert_allclose(linear[..., :3], 2 ** 0.5 * base[..., :3], rtol=2e-6, atol=1e-7)
