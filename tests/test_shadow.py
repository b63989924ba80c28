"""Shadows (`jaxskin.shadow`): the edge of a known occluder's shadow where geometry puts it,
no self-shadowing on a convex body, nothing traced without shadows, gradients with them."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import check_grads_scaled

from jaxskin import render, shadow
from jaxskin.mesh import Mesh, vertex_normals
from jaxskin.projection import project
from jaxskin.scene import load_scene


def _grid(x0, x1, y0, y1, z, n):
    """A flat square grid of 2 n² triangles at height z, facing +z."""
    xs, ys = np.linspace(x0, x1, n + 1), np.linspace(y0, y1, n + 1)
    X, Y = np.meshgrid(xs, ys, indexing="xy")
    v = np.stack([X.ravel(), Y.ravel(), np.full(X.size, z)], axis=1)
    i = np.arange(n)[None, :] + (n + 1) * np.arange(n)[:, None]
    a, b, c, d = i.ravel(), i.ravel() + 1, i.ravel() + n + 1, i.ravel() + n + 2
    return v, np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])


def _mesh(parts):
    vs, fs, offset = [], [], 0
    for v, f in parts:
        vs.append(v)
        fs.append(f + offset)
        offset += len(v)
    v, f = np.concatenate(vs), np.concatenate(fs)
    return Mesh("test", v, f, vertex_normals(v, f), None)


# A floor [-1, 1]² at z = 0 and a square occluder [-0.2, 0.2]² floating at z = 0.3; the
# light toward (1, 0, 0.5): a floor point (x, y) is shadowed when its ray toward the light,
# (x + t, y, 0.5 t), crosses the occluder at z = 0.3 (t = 0.6): x ∈ [-0.8, -0.4],
# y ∈ [-0.2, 0.2] (computed by hand, not by the code under test).
FLOOR = _grid(-1, 1, -1, 1, 0.0, 8)
OCCLUDER = _grid(-0.2, 0.2, -0.2, 0.2, 0.3, 2)
LIGHT = (1.0, 0.0, 0.5)


@pytest.mark.parametrize("size", [96, 160])
def test_shadow_edge_of_a_floating_square_where_geometry_puts_it(size):
    mesh = _mesh([FLOOR, OCCLUDER])
    tmap = project("planar", mesh, size)  # texture space: (x, y) of the floor, 1 texel
    smap = shadow.shadow_map(mesh.vertices, mesh.faces, LIGHT, 2 * size)
    lit = shadow.visibility(mesh.vertices, mesh.faces, mesh.normals, tmap.raster, smap)
    # The texel centres in the mesh's x, y (the planar map's inverse).
    scale = (tmap.xy[1, 0] - tmap.xy[0, 0]) / (mesh.vertices[1, 0] - mesh.vertices[0, 0])
    j, i = np.meshgrid(np.arange(size) + 0.5, np.arange(size) + 0.5, indexing="xy")
    x = (j - size / 2) / scale
    y = (size / 2 - i) / scale
    texel = 1.0 / scale
    on_floor = np.asarray(tmap.raster.mask) & ~((np.abs(x) < 0.2) & (np.abs(y) < 0.2))
    # Distance (in texels) of each texel centre outside (+) or inside (−) the hand-computed
    # shadow rectangle.
    outside = np.maximum(np.maximum(-0.8 - x, x + 0.4), np.maximum(-0.2 - y, y - 0.2)) / texel
    shadowed = lit < 0.5
    assert shadowed[on_floor & (outside < -1)].all()  # deep inside: all in shadow
    assert not shadowed[on_floor & (outside > 1)].any()  # beyond a texel: all lit
    # The edge: the shadowed area matches the rectangle's within one texel of perimeter.
    area = 0.4 * 0.4 / texel**2
    assert abs(shadowed[on_floor].sum() - area) < 2 * (0.4 + 0.4) / texel
    assert not shadowed[np.asarray(tmap.raster.mask) & ~on_floor].any()  # the occluder: lit


def test_a_close_occluder_casts_a_shadow_that_touches_it():
    """The bias must not lift a shadow off its occluder (peter-panning): the same square
    0.06 above the floor. By hand: a floor point is shadowed when x + t ∈ [-0.2, 0.2] with
    0.5 t = 0.06, so x ∈ [-0.32, 0.08]; the floor sees x ∈ [-0.32, -0.2] of it (5.5 texels
    at 96), where the occluder lies 0.12 |(1, 0, 0.5)| = 0.134 toward the light. The bias
    there is (1.5 + tan 63.4°) shadow texels = 0.038 (a shadow texel is 1/92 here), a
    quarter of the gap; ten times it (0.18) lights the whole strip."""
    size = 96
    mesh = _mesh([FLOOR, _grid(-0.2, 0.2, -0.2, 0.2, 0.06, 2)])
    tmap = project("planar", mesh, size)
    smap = shadow.shadow_map(mesh.vertices, mesh.faces, LIGHT, 2 * size)
    lit = shadow.visibility(mesh.vertices, mesh.faces, mesh.normals, tmap.raster, smap)
    scale = (tmap.xy[1, 0] - tmap.xy[0, 0]) / (mesh.vertices[1, 0] - mesh.vertices[0, 0])
    j, i = np.meshgrid(np.arange(size) + 0.5, np.arange(size) + 0.5, indexing="xy")
    x, y = (j - size / 2) / scale, (size / 2 - i) / scale
    on_floor = np.asarray(tmap.raster.mask) & ~((np.abs(x) < 0.2) & (np.abs(y) < 0.2))
    outside = np.maximum(np.maximum(-0.32 - x, x - 0.08), np.maximum(-0.2 - y, y - 0.2)) * scale
    deep = on_floor & (outside < -1)
    assert deep.sum() > 50  # the strip between the occluder's edge and the shadow's
    assert (lit[deep] < 0.5).all()
    assert not (lit[on_floor & (outside > 1)] < 0.5).any()


def test_a_convex_body_does_not_shadow_itself():
    """A sphere: every point facing the light is lit (bias enough against acne), every
    point facing away is behind the lit side."""
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=4)
    v, f = np.asarray(s.vertices), np.asarray(s.faces)
    n = vertex_normals(v, f)
    direction = np.array([0.3, -0.5, 0.8])
    L = direction / np.linalg.norm(direction)
    smap = shadow.shadow_map(v, f, direction, 256)
    # Points on the faces (centroids), with the face's interpolated normal.
    points, normals = v[f].mean(axis=1), n[f].mean(axis=1)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    lit = shadow.lit(smap, points, normals)
    cos = normals @ L
    assert lit[cos > 0.05].all()  # 0.05: N·L at which the slope bias (tan ≈ 8) saturates
    assert not lit[cos < -0.2].any()


def test_shadows_off_traces_no_shadow_code(monkeypatch):
    def refuse(*a, **k):
        raise AssertionError("shadow map made for a scene without shadows")

    small = ["texture.size=32", "camera.size=16"]
    on = load_scene("face", small)
    off = load_scene("face", [*small, "light.shadows=false"])
    assert on.config.shadow is not None and off.config.shadow is None
    on_arrays = render.prepare(on.config).arrays
    assert on_arrays["lit"].shape == on_arrays["texels"].shape  # per texel on the mesh
    monkeypatch.setattr(shadow, "shadow_map", refuse)
    arrays = render.prepare(off.config).arrays
    assert "lit" not in arrays

    def inputs(config, arrays):  # the shapes of the arrays the trace reads
        closed = jax.make_jaxpr(lambda p: render._render.__wrapped__(config, p, arrays))(
            off.params)
        return {(v.aval.shape, str(v.aval.dtype)) for v in closed.jaxpr.constvars}

    per_texel = (on_arrays["lit"].shape, "float32")
    assert per_texel in inputs(on.config, on_arrays)
    assert per_texel not in inputs(off.config, arrays)


def test_shadows_darken_the_face_and_the_blur_softens_their_edges():
    """Shadows on: some of the face darker, none brighter. The shadow term (with − without
    shadows) has softer edges with SSS, most in red (skin scatters red farthest): its
    squared differences between neighbouring pixels inside the face add up to 0.34 with
    the blur against 0.64 without (measured, 128 texels, 96 pixels); green and blue are
    within 1 %."""
    small = ["texture.size=128", "camera.size=96", "camera.supersample=1"]
    images = {}
    for sh in ("true", "false"):
        for sss_on in ("true", "false"):
            sc = load_scene("face", [*small, f"light.shadows={sh}", f"sss.enabled={sss_on}"])
            images[sh, sss_on] = np.asarray(render.render(sc.config, sc.params))
    on = images["false", "false"].sum(-1) > 0
    inner = on.copy()  # pixels whose 3 × 3 neighbourhood is all face: no silhouette
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            inner &= np.roll(on, (dy, dx), (0, 1))
    energy = {}
    for sss_on in ("true", "false"):
        term = images["true", sss_on] - images["false", sss_on]
        assert term.max() < 1e-6 and term[inner].min() < -0.1
        steps = np.diff(term, axis=1)[inner[:, 1:] & inner[:, :-1]]
        energy[sss_on] = (steps**2).sum(axis=0)
    ratio = energy["true"] / energy["false"]
    assert ratio[0] < 0.75 and np.all(np.abs(ratio[1:] - 1) < 0.05), ratio


def test_a_concrete_light_direction_gets_its_own_shadow_map():
    sc = load_scene("face", ["texture.size=32", "camera.size=16"])
    params = {**sc.params, "light.direction": jnp.asarray([-0.6, 0.3, 1.0], jnp.float32)}
    moved = render._shadow_config(sc.config, params)
    assert moved.shadow == pytest.approx((-0.6, 0.3, 1.0))
    assert render._shadow_config(sc.config, sc.params) is sc.config


def _float64(tree):
    return jax.tree.map(lambda a: jnp.asarray(a, jnp.float64)
                        if jnp.issubdtype(jnp.asarray(a).dtype, jnp.floating) else a, tree)


@pytest.fixture(scope="module")
def shadowed():
    """Small face and hand scenes with shadows, prepared in float32 (before `x64`: the
    furrow program is run once per configuration, as the CLI does)."""
    overrides = ["texture.size=32", "camera.size=16", "camera.supersample=1",
                 "light.shadows=true"]
    light = {"face": "[0.5, 0.3, 1.0]", "hand": "[1.0, 0.0, 0.25]"}  # some shadow in each
    scenes = {name: load_scene(name, [*overrides, f"light.direction={d}"])
              for name, d in light.items()}
    return {name: (sc, render.prepare(sc.config).arrays) for name, sc in scenes.items()}


@pytest.mark.parametrize("scene", ["face", "hand"])
def test_render_gradients_with_shadows(shadowed, x64, scene):
    """check_grads (float64, fwd and rev) through a render with shadows on, with respect to
    the light (intensity, direction: the shadow test stays that of the configuration) and
    the material."""
    sc, arrays = shadowed[scene]
    arrays = _float64(arrays)
    assert float(arrays["lit"].min()) == 0.0  # some shadow in the picture
    per = "texels" if scene == "face" else "view_mask"  # per texel (SSS) or per view sample
    assert arrays["lit"].shape == arrays[per].shape
    params = _float64(sc.params)
    keys = ["light.intensity", "light.direction",
            "skin.melanin" if scene == "face" else "material.melanin"]

    def f(*values):
        return render.render_prepared(sc.config, {**params, **dict(zip(keys, values,
                                                                       strict=True))}, arrays)

    values = [params[k] for k in keys]
    scales = [0.1, 1e-2, 0.1]
    check_grads_scaled(f, values, scales, order=1, eps=1e-4, atol=1e-5, rtol=1e-4)
