"""Bump mapping in the surface's own frame (issue 14, item 1): the general form against the
normal of the displaced surface P + k τ h n on a cylinder, at four angles round its axis,
through the cylindrical and the uv projections; eq. 4.10 as its planar case; gradients."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from jaxskin import bump
from jaxskin.mesh import Mesh, vertex_normals
from jaxskin.projection import project
from jaxskin.texture import surface_frame

RADIUS, HALF = 1.0, 1.0  # the cylinder: axis y, y in [−HALF, HALF]
N_THETA, N_Y = 128, 9
SIZE = 256
DEPTH, WIDTH, SLANT = 0.5, 8.0, math.radians(30)  # the furrow: texels, a helix
K = 1.0


def cylinder(uv: bool) -> Mesh:
    """A tube of radius 1 round y; with `uv`, the seam column is doubled and u = θ / 2π,
    v = (y + 1) / 2π (square texels); without, the columns close (cylindrical projection)."""
    cols = N_THETA + 1 if uv else N_THETA
    theta = 2 * math.pi * np.arange(cols) / N_THETA
    y = np.linspace(-HALF, HALF, N_Y)
    T, Y = np.meshgrid(theta, y)  # (N_Y, cols)
    v = np.stack([RADIUS * np.sin(T), Y, RADIUS * np.cos(T)], -1).reshape(-1, 3)
    idx = np.arange(N_Y * cols).reshape(N_Y, cols)
    j1 = np.arange(cols - 1) + 1 if uv else (np.arange(cols) + 1) % cols
    j0 = np.arange(cols - 1) if uv else np.arange(cols)
    a, b = idx[:-1][:, j0], idx[:-1][:, j1]
    c, d = idx[1:][:, j0], idx[1:][:, j1]
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                            np.stack([b, d, c], -1).reshape(-1, 3)])
    normals = vertex_normals(v, faces)
    if np.sum(normals[:, [0, 2]] * v[:, [0, 2]]) < 0:  # outward
        faces = faces[:, ::-1]
        normals = vertex_normals(v, faces)
    texcoords = None
    if uv:
        texcoords = np.stack([T.ravel() / (2 * math.pi), (Y.ravel() + HALF) / (2 * math.pi)], 1)
    return Mesh("tube", v, faces, normals, texcoords)


def furrow_height(theta, y, theta0, texel):
    """h(θ, y): 1 less a Gaussian groove along a helix through θ0, widths in texels."""
    u = (np.mod(theta - theta0 + math.pi, 2 * math.pi) - math.pi) * RADIUS / texel
    d = u * math.cos(SLANT) - (y / texel) * math.sin(SLANT)
    return 1.0 - DEPTH * np.exp(-((d / WIDTH) ** 2))


def displaced_normal(theta, y, theta0, texel):
    """The unit normal of Q(θ, y) = (R + k τ h) e_r + y e_y by central differences, with
    Q_θ taken half a texel ahead in θ and Q_y half a texel ahead in y (where eq. 4.11's
    forward differences sit), Q_θ then turned back by that half texel about the axis (the
    tube's symmetry), so that both are tangents at (θ, y)."""
    def Q(th, yy):
        r = RADIUS + K * texel * furrow_height(th, yy, theta0, texel)
        return np.stack([r * np.sin(th), yy + 0 * th, r * np.cos(th)], -1)

    e = 1e-6
    dth, dy = texel / RADIUS / 2, texel / 2
    q = (Q(theta + dth + e, y) - Q(theta + dth - e, y)) / (2 * e)
    c, s = math.cos(dth), math.sin(dth)
    q_th = np.stack([c * q[..., 0] - s * q[..., 2], q[..., 1], c * q[..., 2] + s * q[..., 0]], -1)
    q_y = (Q(theta, y + dy + e) - Q(theta, y + dy - e)) / (2 * e)
    n = np.cross(q_th, q_y)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def texel_coordinates(tmap):
    """(θ, y) at every texel centre of `tmap` (cylindrical or the tube's uv)."""
    H, W = tmap.height, tmap.width
    j, i = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
    theta = j / W * 2 * math.pi
    if tmap.kind == "cylindrical":
        y = (H / 2 - i) * tmap.texel
    else:
        y = (1 - i / H) * 2 * math.pi * RADIUS - HALF
    return theta, y


def compare(kind, theta0, formula="frame"):
    """max |n_bump − n_ref| / max |n_ref − n| over the furrow's texels."""
    tmap = project(kind, cylinder(kind == "uv"), SIZE)
    n, grads = surface_frame(tmap)
    theta, y = texel_coordinates(tmap)
    texel = 2 * math.pi * RADIUS / SIZE
    h = furrow_height(theta, y, theta0, texel)
    with jax.enable_x64(True):
        n64 = jnp.asarray(n, jnp.float64)
        if formula == "frame":
            out = bump.frame_bump_normals(n64, h, K, *(jnp.asarray(g, jnp.float64) for g in grads),
                                          wrap_s=tmap.wrap_x)
        else:
            out = bump.bump_normals(n64, h, K)
        out, n64 = np.asarray(out), np.asarray(n64)
    ref = displaced_normal(theta, y, theta0, texel)
    # Away from the open ends, whose vertex normals (one-sided sums) lean, and the uv seam
    # (doubled vertices, one-sided too): what is left is the bump's own error.
    inner = np.asarray(tmap.raster.mask) & (np.abs(y) < HALF - 2 * HALF / (N_Y - 1))
    if kind == "uv":
        inner[:, :4] = inner[:, -4:] = False
    near = inner & (h < 1 - 0.01 * DEPTH)
    assert near.sum() > 200
    err = np.linalg.norm(out - ref, axis=-1)[near].max()
    tilt = np.linalg.norm(ref - n64, axis=-1)[near].max()
    return err / tilt


# Measured (float64): relative error 0.014 at every angle, cylindrical and uv (first order
# in k, eq. 4.11's differences, the tube's curvature); the planar formula on the same tube
# is 0.86 off at θ0 = 0 (the seam, no wrap), 1.34 at π/2 (no tilt) and 1.74 at π (mirrored).
@pytest.mark.parametrize("theta0", [0.0, 0.5 * math.pi, math.pi, 1.5 * math.pi])
def test_cylindrical_bump_matches_the_displaced_surface(theta0):
    assert compare("cylindrical", theta0) < 0.1  # furrow at θ0 = 0 crosses the seam


@pytest.mark.parametrize("theta0", [0.25 * math.pi, 0.75 * math.pi, 1.25 * math.pi,
                                    1.75 * math.pi])
def test_uv_bump_matches_the_displaced_surface(theta0):
    assert compare("uv", theta0) < 0.1


def test_eq_4_10_is_wrong_on_the_back_of_a_cylinder():
    """The test can fail: the planar formula (what the arm used) mirrors the tilt at θ = π."""
    assert compare("cylindrical", math.pi, formula="eq4.10") > 1.0


def test_planar_gradients_and_eq_4_10_are_the_general_form(x64):
    """For the planar projection ∇s, ∇t are exactly x and y (texels per texel), and the
    general form equals eq. 4.10 to rounding, n_z → 0 included."""
    mesh = cylinder(False)
    g = project("planar", mesh, 64).gradients()
    np.testing.assert_allclose(g[:, 0], np.broadcast_to([1.0, 0, 0], g[:, 0].shape), atol=1e-12)
    np.testing.assert_allclose(g[:, 1], np.broadcast_to([0, 1.0, 0], g[:, 1].shape), atol=1e-12)
    rng = np.random.default_rng(0)
    n = rng.normal(size=(16, 16, 3))
    n[0, :, 2] = 1e-9  # grazing: n_z → 0
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    h = rng.uniform(size=(16, 16))
    ex = np.broadcast_to([1.0, 0, 0], n.shape)
    ey = np.broadcast_to([0, 1.0, 0], n.shape)
    for k in (0.3, 1.0, 50.0):
        general = bump.frame_bump_normals(n, h, k, ex, ey)
        np.testing.assert_allclose(general, bump.bump_normals(n, h, k), atol=1e-12)


def test_seam_wraps_in_the_height_gradient():
    h = np.zeros((3, 8))
    h[:, 0] = 1.0
    hs, _ = bump.height_gradient(h, wrap_s=True)
    assert np.all(np.asarray(hs)[:, -1] == 1.0)
    hs, _ = bump.height_gradient(h)
    assert np.all(np.asarray(hs)[:, -1] == 0.0)


def _grad_case(kind):
    rng = np.random.default_rng(1)
    n = rng.normal(size=(4, 5, 3))
    gs, gt = rng.normal(size=(2, 4, 5, 3))
    if kind == "grazing":  # ∇s almost along n (a tangent seen edge-on), n_z → 0
        n[..., 2] = 1e-7
        gs = n + 1e-7 * gs
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    n[0, 0] = 0.0  # a texel off the mesh
    return n, rng.uniform(size=(4, 5)), gs, gt


@pytest.mark.parametrize("kind", ["ordinary", "grazing"])
@pytest.mark.parametrize("wrap", [False, True])
def test_frame_bump_gradients(x64, kind, wrap):
    n, h, gs, gt = (jnp.asarray(a, jnp.float64) for a in _grad_case(kind))
    on = jnp.any(n != 0, axis=-1, keepdims=True)  # fixed, as the raster fixes it

    def f(n, h, k, gs, gt):
        return bump.frame_bump_normals(jnp.where(on, n, 0.0), h, k, gs, gt, wrap_s=wrap)

    out = f(n, h, 0.5, gs, gt)
    assert np.all(np.isfinite(out)) and np.all(np.asarray(out)[0, 0] == 0)
    grads = jax.jacrev(lambda *a: f(*a).sum(), argnums=(0, 1, 2, 3, 4))(n, h, 0.5, gs, gt)
    assert all(np.all(np.isfinite(g)) for g in grads)
    check_grads(f, (n, h, jnp.float64(0.5), gs, gt), order=1, modes=("fwd", "rev"))


@pytest.mark.parametrize("wrap", [False, True])
def test_furrows_cross_the_cylinder_seam(wrap):
    """On a cylinder's texture (x periodic) furrows along s run across the seam: none ends
    there, and the columns either side of it match as neighbours inside do. Measured: with
    wrap 0 ends at the seam, correlation 0.78 across it (0.78 between inner neighbours);
    without, 21 ends and −0.07."""
    from jaxskin import wrinkles

    H, W = 48, 96
    field1 = jnp.broadcast_to(jnp.array([1.0, 0.3], jnp.float32), (H, W, 2))
    h, rec = wrinkles.height_field(
        jnp.ones((H, W), bool), field1, jnp.zeros((H, W, 2), jnp.float32),
        jnp.array([[W - 0.5, H / 2]], jnp.float32), 1.0, jax.random.key(0),
        radius=wrinkles.window_radius(1.0), records=256, wrap=wrap)
    r = wrinkles.to_numpy_record(rec, 256)[0]
    end, reason = r["end"].reshape(-1, 2), r["reason"].ravel()
    at_seam = (reason == wrinkles.END_BORDER) & ((end[:, 0] < 1) | (end[:, 0] > W - 1)) & (
        end[:, 1] > 0.5) & (end[:, 1] < H - 0.5)
    h = np.asarray(h)
    across = np.corrcoef(h[:, -1], h[:, 0])[0, 1]
    if wrap:
        assert at_seam.sum() == 0 and across > 0.5
        # s is periodic: the seam is a column pair like any other. Measured: 0.778 across
        # it, 0.682 … 0.87 between inner neighbours (mean 0.79); with the part of a
        # furrow's window past the seam not drawn on the other side, 0.58.
        inner = [np.corrcoef(h[:, j], h[:, j + 1])[0, 1] for j in range(W - 1)]
        assert across >= min(inner)
    else:  # the test can fail: without the wrap the seam cuts the furrows
        assert at_seam.sum() > 5 and across < 0.3


def test_arm_furrows_are_furrows_all_round():
    """The arm scene (cylindrical): in each of 8 sectors round the axis, the normal's shift
    along the circumferential tangent e_s anticorrelates with ∂h/∂s (a furrow's walls face
    its middle). Measured at a 128 texture: −0.976 … −0.987 in every sector; with eq. 4.10
    it was −0.88 … −1.0 on the front and +0.88 … +1.0 on the back (issue 14)."""
    from jaxskin import texture
    from jaxskin.scene import load_scene

    scene = load_scene("arm", ["texture.size=128"])
    maps = texture.texture_maps(scene.config, scene.params)
    s = texture.setup(scene.config.texture)
    hs = np.asarray(bump.height_gradient(maps["height"], wrap_s=True)[0])
    angle = (np.arange(hs.shape[1]) + 0.5) / hs.shape[1] * 2 * math.pi
    e_s = np.stack([np.cos(angle), 0 * angle, -np.sin(angle)], -1)[None]
    shift = np.sum((np.asarray(maps["normals"]) - np.asarray(s.normals)) * e_s, -1)
    for k in range(8):
        sector = np.asarray(s.mask) & (np.floor(angle / (2 * math.pi) * 8) == k)[None]
        assert np.corrcoef(shift[sector], hs[sector])[0, 1] < -0.9
    # The seam's column: ∂h/∂s there is the first column less the last (by hand, not
    # through height_gradient). Measured −0.986 (−0.968 … −0.990 in the other columns).
    h = np.asarray(maps["height"], np.float64)
    seam = np.asarray(s.mask)[:, -1]
    hs_seam = (h[:, 0] - h[:, -1])[seam]
    assert np.corrcoef(shift[:, -1][seam], hs_seam)[0, 1] < -0.9


def test_arm_render_gradients_through_the_frame_bump(x64):
    """check_grads (float64, fwd and rev) of a whole arm render (cylindrical: the general
    form, the seam's wrap) with respect to k_bump, k_noise and the light."""
    from conftest import check_grads_scaled

    from jaxskin import render
    from jaxskin.scene import scene_at_width

    scene = scene_at_width("arm", 32, ["texture.size=48", "wrinkles.k_noise=0.2"])
    arrays = jax.tree.map(lambda a: jnp.asarray(a, jnp.float64)
                          if jnp.issubdtype(jnp.asarray(a).dtype, jnp.floating) else a,
                          render.prepare(scene.config).arrays)
    assert "grad_s" in arrays
    params = jax.tree.map(lambda a: jnp.asarray(a, jnp.float64)
                          if jnp.issubdtype(jnp.asarray(a).dtype, jnp.floating) else a,
                          scene.params)

    def f(k_bump, k_noise, light):
        p = {**params, "wrinkles.k_bump": k_bump, "wrinkles.k_noise": k_noise,
             "light.direction": light}
        return render.render_prepared(scene.config, p, arrays)

    values = [params["wrinkles.k_bump"], params["wrinkles.k_noise"], params["light.direction"]]
    assert np.all(np.isfinite(f(*values)))
    check_grads_scaled(f, values, [0.05, 0.02, 0.05], order=1, eps=1e-4, atol=1e-5, rtol=1e-4)


def test_eq_4_10_on_the_side_facing_minus_z():
    """A planar map's −z side (the palm, "planar-back") is the surface z = −h(x, y) below
    the plane: its outward normal is (−h_x, −h_y, −1)/|…| — the same tangential tilt as the
    +z side's (−h_x, −h_y, 1)/|…|, which eq. 4.10's cross products give for n = ∓z alike
    (derived by hand; here against that closed form)."""
    import jax.numpy as jnp

    from jaxskin.bump import bump_normals, height_gradient

    y, x = np.mgrid[0:16, 0:16].astype(np.float32)
    h = jnp.asarray(0.3 * np.sin(x / 3.0) + 0.2 * np.cos(y / 4.0))
    hs, ht = (np.asarray(g) for g in height_gradient(h))
    k = 0.5
    for sign in (1.0, -1.0):
        n = jnp.zeros((16, 16, 3)).at[..., 2].set(sign)
        got = np.asarray(bump_normals(n, h, k))
        want = np.stack([-k * hs, -k * ht, np.full_like(hs, sign)], axis=-1)
        want /= np.linalg.norm(want, axis=-1, keepdims=True)
        np.testing.assert_allclose(got, want, atol=1e-6)
