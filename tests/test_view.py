"""Camera views: the padding beyond the mesh's texels (no dark rim at silhouettes), alpha."""

import jax.numpy as jnp
import numpy as np
import pytest

from jaxskin import render
from jaxskin.scene import load_scene
from jaxskin.view import coverage, pad_index, sample


def test_pad_index_fills_the_nearest_texel_and_wraps_the_seam():
    mask = np.zeros((7, 10), bool)
    mask[2:5, 0:2] = True  # touches the left edge: across the seam it reaches x = 9, 8
    values = np.arange(70, dtype=float).reshape(7, 10)
    for wrap in (False, True):
        index = pad_index(mask, wrap, width=2)
        padded = values.reshape(-1)[index].reshape(7, 10)
        assert np.array_equal(padded[mask], values[mask])  # on the mesh: itself
        assert padded[3, 2] == values[3, 1] and padded[3, 3] == values[3, 1]  # right side
        assert padded[1, 0] == values[2, 0] and padded[0, 1] == values[2, 1]  # above
        assert padded[3, 4] == values[3, 4]  # beyond the width: untouched
        across = padded[3, 9] == values[3, 0] and padded[3, 8] == values[3, 0]
        assert across == wrap


@pytest.mark.parametrize("scene", ["face", "arm"])
def test_no_dark_rim_where_the_view_samples_beyond_the_mesh(scene):
    """The rim check: a texture-space image that is 1 on the mesh, sampled into the view,
    is 1 at every sample that sees the mesh, silhouettes included; without the padding
    the silhouette's samples read background texels (as low as 0.32 on the face,
    measured) — the check fails there."""
    sc = load_scene(scene, ["texture.size=128", "camera.size=96", "camera.supersample=1"])
    a = render.prepare(sc.config).arrays
    view = render.prepare(sc.config).view
    ones = jnp.where(a["mask"][..., None], 1.0, 0.0)
    padded = ones.reshape(-1, 1)[a["pad"]]
    seen = np.asarray(sample(padded, a["tex"], a["view_mask"], view.wrap_x))[..., 0]
    on = np.asarray(a["view_mask"])
    np.testing.assert_allclose(seen[on], 1.0, atol=1e-6)
    bare = np.asarray(sample(ones, a["tex"], a["view_mask"], view.wrap_x))[..., 0]
    if scene == "face":
        assert bare[on].min() < 0.5


def test_face_silhouette_is_not_darker_than_its_interior():
    """The rendered face with flat normals and no furrows (constant albedo and irradiance
    in texture space): every pixel on the face within 1 % of the median (measured: 0.9969 of it at
    the darkest, the perspective view's highlight varying); without the padding the rim
    fell to 0.32 of it."""
    sc = load_scene("face", ["texture.size=128", "camera.size=96", "camera.supersample=1",
                             "light.shadows=false", "wrinkles.enabled=false"])
    a = render.prepare(sc.config).arrays
    flat = jnp.where(a["mask"][..., None], jnp.asarray([0.0, 0.0, 1.0]), 0.0)
    image = np.asarray(render.render_prepared(sc.config, sc.params, {**a, "normals": flat}))
    v = image.sum(-1)[np.asarray(a["view_mask"])]
    assert v.min() > 0.99 * np.median(v)


def test_alpha_is_the_coverage_and_straight_colour_undoes_it():
    sc = load_scene("face", ["texture.size=64", "camera.size=32", "camera.supersample=2",
                             "light.shadows=false"])
    mask = render.prepare(sc.config).view.mask
    alpha = coverage(mask, 2)
    assert set(np.unique(alpha)) <= {0.0, 0.25, 0.5, 0.75, 1.0} and 0 < alpha.mean() < 1
    rgba = np.asarray(render.render(sc.config, sc.params, "rgba"))
    linear = np.asarray(render.render(sc.config, sc.params, "linear_rgba"))
    display = np.asarray(render.render(sc.config, sc.params))
    np.testing.assert_array_equal(rgba[..., 3], alpha)
    np.testing.assert_array_equal(linear[..., 3], alpha)
    assert np.all(rgba[alpha == 0, :3] == 0)
    # Over black, straight colour × alpha is the premultiplied linear light; encoded, the
    # display image.
    from jaxskin.render import decode_srgb, encode_srgb

    np.testing.assert_allclose(decode_srgb(rgba[..., :3]) * alpha[..., None],
                               linear[..., :3], atol=1e-5)
    np.testing.assert_allclose(encode_srgb(linear[..., :3]), display, atol=1e-5)


@pytest.mark.parametrize("projection", ["orthographic", "perspective"])
def test_camera_zoom_is_a_crop_of_a_larger_image(projection):
    """camera.zoom 2 about camera.center (0.25, 0.25) is the top-right quarter of the same
    view rendered at twice the size, pixel for pixel: the zoom only crops the image plane
    (the pinhole and the texture-space stages stay put). Measured: identical (0.0)."""
    base = ["texture.size=64", "camera.supersample=2", f"camera.projection={projection}"]
    big = load_scene("hand", base + ["camera.size=64"])
    close = load_scene("hand", base + ["camera.size=32", "camera.zoom=2",
                                       "camera.center=[0.25, 0.25]"])
    whole = np.asarray(render.render(big.config, big.params, output="linear_rgba"))
    zoomed = np.asarray(render.render(close.config, close.params, output="linear_rgba"))
    quarter = whole[:32, 32:]
    assert quarter[..., 3].mean() > 0.2  # the quarter shows the hand, not background
    np.testing.assert_allclose(zoomed, quarter, rtol=0, atol=1e-6)
    # and it is not the whole image shrunk, nor another quarter
    assert np.abs(zoomed - whole[32:, :32]).max() > 0.1


@pytest.mark.parametrize("over", [["camera.fov=60"], ["camera.fov=120"],
                                  ["camera.rotate=[0, 40, 0]"], ["camera.rotate=[30, 0, 0]"],
                                  ["camera.height=40"], ["camera.height=160"]],
                         ids=["fov60", "fov120", "turned", "tilted", "wide", "tall"])
def test_a_perspective_view_keeps_the_whole_mesh_inside_the_margin(over):
    """Every vertex of the face projects inside the frame less the 5 % margin on each side,
    and the projection is centred, at any field of view and turn (a pinhole placed where
    only the bounding box's middle fits cut off the forehead and chin at fov 60 and a
    turned face's side); the frame is filled: one of the two extents meets the margin."""
    from jaxskin.view import MARGIN

    sc = load_scene("face", ["texture.size=64", "camera.size=80", "camera.supersample=1",
                             "camera.projection=perspective", *over])
    view = render.prepare(sc.config).view
    H, W = view.mask.shape
    u, v = view.xy[:, 0] / W, view.xy[:, 1] / H
    lo, hi = MARGIN - 1e-6, 1 - MARGIN + 1e-6
    assert u.min() >= lo and u.max() <= hi and v.min() >= lo and v.max() <= hi
    assert max(u.max() - u.min(), v.max() - v.min()) == pytest.approx(1 - 2 * MARGIN, abs=1e-6)
    np.testing.assert_allclose([u.min() + u.max(), v.min() + v.max()], 1.0, atol=1e-6)
    edge = np.concatenate([view.mask[0], view.mask[-1], view.mask[:, 0], view.mask[:, -1]])
    assert not edge.any()


def test_a_flat_mesh_facing_a_perspective_camera_fills_the_frame_as_orthographic():
    """With no depth, the perspective framing is the orthographic one: the square's
    corners at the margin in both."""
    from jaxskin.mesh import Mesh
    from jaxskin.projection import project
    from jaxskin.view import MARGIN, make_view

    v = np.array([[-1, -2, 0], [3, -2, 0], [3, 1, 0], [-1, 1, 0.0]])
    mesh = Mesh("rect", v, np.array([[0, 1, 2], [0, 2, 3]]), np.tile([0, 0, 1.0], (4, 1)),
                None)
    tmap = project("planar", mesh, 16)
    for projection in ("orthographic", "perspective"):
        view = make_view(tmap, 100, projection, fov=50.0)
        x, y = view.xy[:, 0], view.xy[:, 1]
        np.testing.assert_allclose([x.min(), x.max()], [100 * MARGIN, 100 * (1 - MARGIN)],
                                   atol=1e-6)
        np.testing.assert_allclose([y.min(), y.max()], [50 - 90 * 3 / 8, 50 + 90 * 3 / 8],
                                   atol=1e-6)


def _sphere_with_a_hole(tmp_path):
    """A sphere (radius 20 mm) with its cap toward the camera (+z) cut away, as a scene."""
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=3, radius=20.0)
    keep = s.triangles_center[:, 2] < 12.0
    trimesh.Trimesh(s.vertices, s.faces[keep], process=False).export(tmp_path / "hole.obj")
    (tmp_path / "hole.toml").write_text('[mesh]\nfile = "hole.obj"\nprojection = "planar"\n')
    return tmp_path / "hole.toml"


@pytest.mark.parametrize("model", ["blinn", "lafortune", "spectral"])
def test_the_inside_of_an_open_mesh_is_black_whatever_the_light(tmp_path, model):
    """Through an open mesh's opening the camera sees the back of triangles, whose texels
    hold the outside's shading: the inside of a sphere with a hole would be lit by a light
    behind the sphere (0.60 where the light cannot reach) and flat under a light from the
    camera. Those samples are black, opaque (alpha 1), under either light;
    the sphere's outside (the ring round the hole) is lit by the light from the camera."""
    path = _sphere_with_a_hole(tmp_path)
    common = ["texture.size=64", "camera.size=64", "camera.supersample=1",
              f"material.model={model}", "light.ambient=0.2"]
    behind = load_scene(path, [*common, "light.direction=[0, 0, -1]"])
    front = load_scene(path, [*common, "light.direction=[0, 0, 1]"])
    view = render.prepare(behind.config).view
    inside = view.mask & ~view.front
    assert inside.sum() > 400 and np.array_equal(view.shaded, view.mask & view.front)
    for sc in (behind, front):
        rgba = np.asarray(render.render(sc.config, sc.params, "linear_rgba"))
        assert np.all(rgba[inside][:, :3] == 0.0) and np.all(rgba[inside][:, 3] == 1.0)
    rgba = np.asarray(render.render(front.config, front.params, "linear_rgba"))
    assert rgba[view.front][:, :3].mean() > 0.1  # measured 0.16 (Blinn)


@pytest.mark.parametrize("scene", ["hand", "foot", "arm", "face"])
def test_the_built_in_views_see_no_triangle_from_behind(scene):
    """So the black inside changes none of them (their openings face away)."""
    view = render.prepare(load_scene(scene, ["texture.size=128", "camera.size=96"]).config).view
    assert view.mask.sum() > 1000 and np.array_equal(view.front, view.mask)


def test_a_planar_scene_seen_from_behind_is_lit_and_a_side_view_warned():
    """The hand turned 180° about y must not show its palm shaded with the back's texels
    (their normals face away from the light): a flat silhouette, mean (108, 87, 75) with
    little variation. A camera that sees the −z side gives that side the shared
    texels ("planar-back"), so the palm is lit like the back (its mean within 5 % of the
    front view's) and keeps its furrows; a view from the side, where the two sides'
    texels interleave, is warned; no built-in scene's own view is."""
    import numpy as np

    from jaxskin import render
    from jaxskin.checks import hidden_side
    from jaxskin.scene import load_scene

    small = ["texture.size=128", "camera.size=64"]
    for name in ("hand", "foot", "arm", "face", "makeup"):
        assert hidden_side(load_scene(name, small)) == [], name
    front = load_scene("hand", small)
    back = load_scene("hand", [*small, "camera.rotate=[0,180,0]"])
    assert (front.config.texture.projection, back.config.texture.projection) == (
        "planar", "planar-back")
    assert hidden_side(back) == []
    side = hidden_side(load_scene("foot", [*small, "camera.rotate=[0,-70,0]"]))
    assert len(side) == 1 and "of the view is a side of the mesh that the planar " \
        "projection shades with the other side's texels" in side[0], side
    means, spreads = [], []
    for sc in (front, back):
        image = np.asarray(render.render(sc.config, sc.params))
        skin = image[image.sum(-1) > 0]
        means.append(skin.mean(0))
        spreads.append(skin.std(0))
    np.testing.assert_allclose(means[1], means[0], rtol=0.05)
    assert np.all(spreads[1] > 0.7 * spreads[0]), spreads  # shaded, not a flat silhouette


@pytest.mark.parametrize("rotate", [(0, 180, 0), (180, 0, 0), (0, 180, 30), (170, 10, 0),
                                    (0, 0, 0), (0, 0, 90)])
def test_the_field_plot_shows_the_back_side_the_way_the_render_does(rotate):
    """The hand seen from −z: mirroring x in the field plot for every such view would show
    a turn about x (upside down in the render) turned half round against it.
    The plot's x and y of a point have the signs the render's rotation gives them."""
    from jaxskin.maps import plot_flip
    from jaxskin.scene import planar_side
    from jaxskin.view import rotation

    side = -1 if planar_side("planar", rotate) == "planar-back" else 1
    flip = plot_flip(side, rotate)
    assert np.prod(flip) == 1  # a turn, not a mirror image
    if side > 0:
        assert flip.tolist() == [1, 1, 1]  # the front: the mesh's own axes
        return
    p = np.array([1.0, 1.0, 0.0])
    seen = rotation(rotate) @ p
    r = np.radians(rotate[2])  # an in-plane turn last: compare before it
    seen = np.array([[np.cos(r), np.sin(r), 0], [-np.sin(r), np.cos(r), 0], [0, 0, 1]]) @ seen
    assert np.array_equal(np.sign(flip[:2] * p[:2]), np.sign(seen[:2])), (flip, seen)
