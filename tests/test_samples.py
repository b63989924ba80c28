"""Blinn and Lafortune shade only the view's samples on the mesh (`jaxskin.samples`)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from jaxskin import render
from jaxskin.samples import BUCKETS, sample_list, to_pixels
from jaxskin.scene import scene_at_width
from jaxskin.view import downsample


def _view(seed=0, k=2, H=5, W=7):
    rng = np.random.default_rng(seed)
    shaded = rng.random((k * H, k * W)) < 0.4
    tex = rng.random((k * H, k * W, 2)).astype(np.float32) * 10
    return shaded, tex


def test_the_list_holds_the_shaded_samples_and_pads_to_a_bucket():
    shaded, tex = _view()
    t = sample_list(tex, shaded, 2)
    M, n = int(shaded.sum()), shaded.size
    step = -(-n // BUCKETS)
    assert t["list_tex"].shape == (-(-M // step) * step, 2)
    assert t["list_on"].sum() == M and not t["list_on"][M:].any()
    assert np.array_equal(t["list_index"][:M], np.flatnonzero(shaded))
    assert np.array_equal(t["list_tex"][:M], tex.reshape(-1, 2)[np.flatnonzero(shaded)])
    # each pixel lists its own samples only: its 2 x 2 block, in the block's row order
    rows, cols = np.nonzero(shaded)
    for i, (r, c) in enumerate(zip(rows, cols, strict=True)):
        assert t["list_pixel"][i] == (r // 2) * 7 + c // 2
        assert t["pixel_list"][t["list_pixel"][i], (r % 2) * 2 + c % 2] == i
    with pytest.raises(ValueError, match="cannot hold"):
        sample_list(tex, shaded, 2, length=M - 1)


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
    got = np.asarray(to_pixels(values, t["list_pixel"], t["pixel_list"], (5, 7)))
    np.testing.assert_allclose(got, expected, rtol=0, atol=2e-7)


def test_the_pixel_mean_is_gradient_checked(x64):
    shaded, tex = _view(3)
    t = sample_list(tex, shaded, 2)
    values = jnp.asarray(np.random.default_rng(4).normal(size=(t["list_on"].size, 3)))

    @jax.jit  # one program each way, not op by op
    def f(v):
        return to_pixels(v, t["list_pixel"], t["pixel_list"], (5, 7)) ** 2

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
    assert seen <= a["list_tex"].shape[0] <= seen + total // BUCKETS
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
size = 64
[camera]
size = 64
supersample = 2
"""


def test_the_editor_turns_a_blinn_hand_without_a_new_program(tmp_path):
    """The render's list is as long as the samples on the mesh, which a turn changes; the
    editor lists every sample instead, so a turn or a zoom compiles nothing new, and each
    image is still `jaxskin render`'s."""
    pytest.importorskip("aiohttp", reason="the editor needs aiohttp (the edit extra)")
    from jaxskin.editor import Session

    (tmp_path / "tiny_hand.toml").write_text(HAND)
    (tmp_path / "out").mkdir()
    s = Session(str(tmp_path / "tiny_hand.toml"), tmp_path / "out")
    s.render()
    lengths = set()
    for changes in ({"camera.rotate": [10.0, 25.0, 0.0]}, {"camera.zoom": 2.0},
                    {"camera.rotate": [-40.0, 60.0, 0.0], "camera.zoom": 1.0}):
        compiled = render._render._cache_size()
        s.set(changes)
        image = s.render()
        assert render._render._cache_size() == compiled, changes
        lengths.add(render.prepare(s.scene.config).arrays["list_tex"].shape[0])
        expected = np.asarray(render.render(s.scene.config, s.scene.params))
        np.testing.assert_array_equal(np.round(np.clip(image, 0, 1) * 255),
                                      np.round(np.clip(expected, 0, 1) * 255))
    assert len(lengths) > 1  # the CLI's lists differ: the editor's one program covers them


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
