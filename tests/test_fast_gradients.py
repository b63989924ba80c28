"""The hand-written reverse-mode rules (issue 19, item 2): the makeup model's spectral
cotangents (`layered._cotangents`) and the view sampling's transpose table
(`view.transpose_table`), against JAX's autodiff of the plain forward in float64, at ordinary
and stiff points; forward mode (jvp, jacfwd, vmap) through `linear.linear_call` kept."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import check_grads_scaled

from jaxskin import formats, km, render, spectral, view
from jaxskin.linear import linear_call
from jaxskin.scene import load_scene
from jaxskin.shading import layered

GRID = spectral.Grid(step=20)


def _spectral_inputs(point, per_texel_skin, P=40, L=4, seed=0):
    """`(X, E, h, h_l, S, K, skin_R)` on GRID; `point`: ordinary values, or the stiff ones
    (thickness 0 and 10 mm, K = 0, S = 0, K = 1e-9, X = 1e-7)."""
    rng = np.random.default_rng(seed)
    n = len(GRID)
    S = rng.uniform(5, 60, (L, n))
    K = rng.uniform(0.5, 30, (L, n))
    X = rng.uniform(0, 0.03, (L, P))
    if point == "stiff":  # (K → 0 under a thick layer is left out: ∂R/∂K → −∞ there)
        X[0, :5] = 0.0
        X[1, 5:9] = 10.0  # opaque
        X[2, 9:12] = 1e-7
        X[:, 12:14] = 0.0  # no layer at all
        X[L - 1, 16:] = 0.0  # absent from whole chunks of 16: its S, K sums skipped there
        K[2, :4] = 0.0
        S[0, :3] = 0.0
        K[0, 4:6] = 1e-9
        S[2, 6] = 0.0
        K[2, 6] = 1e-9
    E = rng.uniform(0.2, 1.0, (P, 1))
    h = rng.uniform(0.0, 0.3, (P, 1))
    h_l = rng.uniform(0.0, 0.3, (L, P, 1))
    skin = formats.nist_reflectance(3, GRID)
    if per_texel_skin:
        skin = skin * rng.uniform(0.3, 1.0, (P, 1))
    return tuple(jnp.asarray(a, jnp.float64) for a in (X, E, h, h_l, S, K, skin))


@pytest.mark.parametrize("point", ["ordinary", "stiff"])
@pytest.mark.parametrize("per_texel_skin", [False, True], ids=["skin per band", "skin map"])
@pytest.mark.parametrize("blurred", [False, True], ids=["unblurred", "blurred"])
def test_cotangents_equal_autodiff_of_the_plain_forward(x64, monkeypatch, blurred,
                                                        per_texel_skin, point):
    """Every cotangent of `_colours` (X, E, h, h_l, S, K, skin), by hand, against jax.vjp of
    `_joint` (the same colours in one plain program), to 1e-10 of the largest entry, with
    XLA:CPU's forms on any device."""
    monkeypatch.setattr(layered, "_cpu_form", lambda name: True)
    # ragged chunks, two a step (the CPU's default); at the stiff point also one and three,
    # and all 40 texels as one chunk (the chunking does not depend on the values)
    ways = ((16, 1), (16, 2), (16, 3), (40, 1)) if point == "stiff" else ((16, 2),)
    _check_cotangents(blurred, per_texel_skin, point, ways)


@pytest.mark.parametrize("per_texel_skin", [False, True], ids=["skin per band", "skin map"])
@pytest.mark.parametrize("blurred", [False, True], ids=["unblurred", "blurred"])
def test_the_forms_a_gpu_traces_equal_autodiff(x64, monkeypatch, blurred, per_texel_skin):
    """The same at the stiff point with the forms a GPU traces (`layered._cpu_form` False:
    wide chunks, the colours in one program, no skipped layers, plain sums), so that a
    CPU-only run checks them too; every form is asked for. WIDE_CHUNK 16 makes the 40
    texels three equal chunks of 14, the last padded, and the tangent's chunks 2 texels."""
    asked = set()

    def plain(name):
        asked.add(name)
        return False

    monkeypatch.setattr(layered, "_cpu_form", plain)
    monkeypatch.setattr(layered, "WIDE_CHUNK", 16)
    assert layered._chunking(40) == (14, 1) and layered._chunking(0) == (1, 1)
    _check_cotangents(blurred, per_texel_skin, "stiff", ((None, None), (16, 3)))
    assert asked >= {"chunks", "skip", "sums"}, asked
    # The colours and their tangent (forward mode: `_chunked_tangent`) against the CPU's forms.
    args = _spectral_inputs("stiff", per_texel_skin)
    tangents = tuple(jnp.asarray(np.random.default_rng(3).normal(size=a.shape)) for a in args)

    def colours_and_tangent():
        return jax.jvp(lambda *a: layered._colours(GRID, blurred, *a), args, tangents)

    together = colours_and_tangent()
    assert "forward" in asked
    monkeypatch.setattr(layered, "_cpu_form", lambda name: True)
    for plain, cpu in zip(together, colours_and_tangent(), strict=True):
        assert float(jnp.max(jnp.abs(plain - cpu))) <= 1e-12 * float(jnp.max(jnp.abs(cpu)))


@pytest.mark.parametrize("per_texel_skin", [False, True], ids=["skin per band", "skin map"])
@pytest.mark.parametrize("blurred", [False, True], ids=["unblurred", "blurred"])
def test_the_chunked_forward_equals_the_plain_one(x64, monkeypatch, blurred, per_texel_skin):
    """`layered._forward_chunked` (the CPU's value of `_colours`: a layer absent from a chunk
    skipped, one uniform over it computed per band) against `_joint` over every texel, to
    1e-13 of the largest entry (the skipped layer changes nothing, bit for bit; fused
    multiply-adds may round the rest differently). Chunks of 4 texels: the 42 texels give
    chunks where the bottom layer and a layer above it are absent, uniform (at 0.02 mm, and
    at 10 mm: opaque) and varying, and a padded last chunk."""
    args = list(_spectral_inputs("stiff", per_texel_skin, P=42))
    X = np.array(args[0])
    X[0, 20:28] = 0.0  # the bottom layer absent from two chunks, uniform over the next two
    X[0, 28:36] = 0.02
    X[2, 20:24] = 0.0
    X[2, 24:28] = 10.0
    X[1, 32:36] = 0.0
    args[0] = jnp.asarray(X)
    monkeypatch.setattr(layered, "FORWARD_CHUNK", 4)
    want = jax.jit(lambda a: layered._joint(GRID, blurred, *a))(args)
    got = jax.jit(lambda a: layered._forward_chunked(GRID, blurred, *a))(args)
    assert got.shape == want.shape
    assert float(jnp.max(jnp.abs(got - want))) <= 1e-13 * float(jnp.max(jnp.abs(want)))


def _check_cotangents(blurred, per_texel_skin, point, ways):
    """`_cotangents` and `_cotangents_chunked` with each `(chunk, streams)` of `ways`
    (None: `_chunking`'s) against `jax.vjp` of `_joint`, to 1e-10 of the largest entry."""
    args = _spectral_inputs(point, per_texel_skin)

    @jax.jit  # each side one program (run op by op, the hand-written pass took 10 s)
    def autodiff(args, g):
        return jax.vjp(lambda *a: layered._joint(GRID, blurred, *a), *args)[1](g)

    out = jax.jit(lambda a: layered._joint(GRID, blurred, *a))(args)
    assert bool(jnp.all(jnp.isfinite(out)))
    g = jnp.asarray(np.random.default_rng(1).normal(size=out.shape))
    expected = autodiff(args, g)
    got = jax.jit(lambda a, g: layered._cotangents(GRID, blurred, *a, g))(args, g)
    chunked = [layered._cotangents_chunked(GRID, blurred, *args, g, chunk=c, streams=k)
               for c, k in ways]
    for name, e, a, *cs in zip("X E h h_l S K skin".split(), expected, got, *chunked,
                               strict=True):
        assert a.shape == e.shape, name
        scale = float(jnp.max(jnp.abs(e)))
        assert scale > 0, name
        assert float(jnp.max(jnp.abs(a - e))) <= 1e-10 * scale, name
        for c in cs:
            assert c.shape == e.shape, name
            assert float(jnp.max(jnp.abs(c - e))) <= 1e-10 * scale, name


@functools.cache
def _colours_jitted(blurred):
    """`_colours`, jitted once per `blurred` for the module: the ordinary and the stiff
    point share its programs (check_grads' jvp and vjp) instead of running op by op."""
    return jax.jit(lambda *a: layered._colours(GRID, blurred, *a))


@pytest.mark.parametrize("point", ["ordinary", "stiff"])
@pytest.mark.parametrize("blurred", [False, True], ids=["unblurred", "blurred"])
def test_colours_check_grads(x64, blurred, point):
    """`_colours` itself (the custom JVP whose transpose is `_cotangents`): check_grads fwd and
    rev, float64, with respect to every input, at ordinary and stiff points."""
    args = _spectral_inputs(point, per_texel_skin=False, P=24, L=3, seed=2)
    scales = [1e-3, 0.01, 0.01, 0.01, 0.5, 0.5, 0.01]

    f = _colours_jitted(blurred)
    check_grads_scaled(f, list(args), scales, order=1, eps=1e-4, atol=1e-7, rtol=1e-5)
    grads = jax.jit(jax.grad(lambda *a: jnp.sum(f(*a)), argnums=tuple(range(7))))(*args)
    assert all(bool(jnp.all(jnp.isfinite(x))) for x in grads)


def test_forward_mode_and_vmap_through_linear_call(x64):
    """jacfwd (vmap of forward mode) and jacrev of a small makeup render agree: forward mode
    evaluates the tangent, reverse mode the hand-written transposes."""
    sc = load_scene("makeup", ["texture.size=32", "camera.size=16"])
    arrays = jax.tree.map(lambda a: jnp.asarray(a, jnp.float64)
                          if jnp.issubdtype(a.dtype, jnp.floating) else a,
                          render.prepare(sc.config).arrays)
    params = jax.tree.map(lambda a: jnp.asarray(a, jnp.float64), sc.params)
    keys = ["layer.foundation.thickness_mm", "layer.blush.k_scale", "skin.melanin"]

    def f(v):
        p = {**params, **{k: v[i] for i, k in enumerate(keys)}}
        return render.render_prepared(sc.config, p, arrays)[4:12, 4:12].reshape(-1)

    v = jnp.asarray([float(params[k]) for k in keys])
    fwd, rev = jax.jacfwd(f)(v), jax.jacrev(f)(v)
    assert float(jnp.abs(fwd).max()) > 0
    np.testing.assert_allclose(fwd, rev, rtol=0, atol=1e-12 * float(jnp.abs(fwd).max()))


def test_linear_call_transposes_by_hand_and_batches():
    """A toy: fun scales by 2, its 'transpose' by 3 (deliberately not fun's), so the test
    sees which rule ran; forward mode and vmap."""
    def fun(r, x):
        return 2.0 * r * x

    def transpose(r, ct):
        return (3.0 * r * ct,)

    @jax.custom_jvp
    def f(r, x):
        return 2.0 * r * x

    @f.defjvp
    def f_jvp(primals, tangents):
        r, x = primals
        return f(r, x), linear_call(fun, transpose, (r,), (tangents[1],))

    x = jnp.arange(3.0)
    assert float(jax.grad(lambda x: jnp.sum(f(1.5, x)))(x)[0]) == 4.5  # the hand rule: 3 r
    assert float(jax.jvp(lambda x: f(1.5, x), (x,), (jnp.ones(3),))[1][0]) == 3.0  # 2 r
    assert jnp.array_equal(jax.jacfwd(lambda x: f(1.5, x))(x), 3.0 * jnp.eye(3))
    batched = jax.vmap(jax.grad(lambda x: jnp.sum(f(1.5, x))))(jnp.ones((2, 3)))
    assert batched.shape == (2, 3)  # batched: vmap of fun, JAX's own transpose (2 r)


@pytest.mark.parametrize("scene", ["makeup", "hand"])
def test_view_transpose_table_equals_autodiff(x64, scene):
    """The gradient of a sampled view with respect to the texture image, by the transpose
    table, equals JAX's transpose of the plain gathers (float64, exact up to rounding); every
    sample's four weights are in the table once."""
    sc = load_scene(scene, ["texture.size=48", "camera.size=24"])
    p = render.prepare(sc.config)
    a = p.arrays
    t = view.transpose_table(a["tex"], a["view_mask"], a["pad"], a["mask"].shape,
                             p.view.wrap_x)  # (the makeup scene's render uses pixel_table)
    table = [jnp.asarray(t[k]) for k in render.VIEW_TABLE]
    assert float(np.sum(t["view_weights"])) == pytest.approx(float(np.sum(a["view_mask"])),
                                                             rel=1e-6)
    rng = np.random.default_rng(4)
    image = jnp.asarray(rng.uniform(size=(*a["mask"].shape, 3)))
    W = jnp.asarray(rng.normal(size=(*a["view_mask"].shape, 3)))

    @jax.jit  # (each program whole, not op by op)
    def loss(image, table):
        return jnp.sum(W * view.sample_padded(image, a["pad"], jnp.asarray(a["tex"], jnp.float64),
                                              a["view_mask"], p.view.wrap_x, table))

    assert float(loss(image, table)) == float(loss(image, None))
    fast, plain = jax.grad(loss)(image, table), jax.grad(loss)(image, None)
    assert float(jnp.abs(plain).max()) > 0
    np.testing.assert_allclose(fast, plain, rtol=0, atol=1e-13)
    check_grads_scaled(jax.jit(lambda im: view.sample_padded(im, a["pad"], a["tex"],
                                                             a["view_mask"], p.view.wrap_x,
                                                             table)),
                       [image], [0.1], order=1)


@pytest.mark.parametrize("scene", ["makeup", "arm"])
def test_the_pixel_table_is_sampling_then_averaging(x64, scene):
    """`view.view_pixels` (the cosmetics model's view: one table each way) against the two
    steps it replaces, `downsample(sample_padded(...))`, computed in float64 from the
    coordinates: the same map up to its float32 weights (measured 2e-8 of values in
    [0, 1]); its reverse mode, by the transposed table, equals JAX's transpose of its own
    forward exactly, and of the two steps to the same 1e-7; check_grads fwd and rev. The
    perspective face and the arm (a cylinder: x wraps)."""
    sc = load_scene(scene, ["texture.size=48", "camera.size=24"])
    p = render.prepare(sc.config)
    a, k = p.arrays, sc.config.supersample
    t = view.pixel_table(a["tex"], a["view_mask"], a["pad"], a["mask"].shape, p.view.wrap_x, k)
    table = [jnp.asarray(t[name]) for name in view.PIXEL_TABLE]
    assert float(np.sum(t["pix_w"])) == pytest.approx(float(np.sum(a["view_mask"])) / k / k,
                                                      rel=1e-6)
    np.testing.assert_allclose(np.sum(t["pix_w"]), np.sum(t["pix_t_w"]), rtol=1e-6)
    rng = np.random.default_rng(5)
    image = jnp.asarray(rng.uniform(size=(*a["mask"].shape, 3)))
    H, W = a["view_mask"].shape[0] // k, a["view_mask"].shape[1] // k
    W_ = jnp.asarray(rng.normal(size=(H, W, 3)))
    tex = jnp.asarray(a["tex"], jnp.float64)

    @jax.jit  # (each program whole, not op by op)
    def two_steps(im):
        return view.downsample(view.sample_padded(im, a["pad"], tex, a["view_mask"],
                                                  p.view.wrap_x), k)

    @jax.jit
    def one_map(im):
        return view.view_pixels(im, table, (H, W))

    np.testing.assert_allclose(one_map(image), two_steps(image), rtol=0, atol=1e-7)
    fast = jax.grad(lambda im: jnp.sum(W_ * one_map(im)))(image)
    plain = jax.grad(lambda im: jnp.sum(W_ * two_steps(im)))(image)
    np.testing.assert_allclose(fast, plain, rtol=0, atol=1e-6 * float(jnp.abs(plain).max()))

    @jax.jit
    def plain_map(im):  # the forward table applied with plain JAX ops: JAX transposes it
        flat = im.reshape(-1, 3)
        w = jnp.asarray(t["pix_w"], jnp.float64)
        read = jnp.stack([jnp.sum(flat[:, c][t["pix_src"]] * w, axis=1) for c in range(3)], -1)
        return jnp.zeros((H * W, 3)).at[t["pix_dest"]].add(read).reshape(H, W, 3)

    exact = jax.grad(lambda im: jnp.sum(W_ * plain_map(im)))(image)
    np.testing.assert_allclose(fast, exact, rtol=0, atol=1e-13)
    check_grads_scaled(one_map, [image], [0.1], order=1)


def test_layer_S_K_cotangents_equal_autodiff_of_km_layer(x64):
    """`layered._layer_SK` (the S and K cotangents of one KM layer through q = K(K + 2S),
    from `km.layer_parts`, no second evaluation of the layer) against `jax.vjp` of
    `km.layer`, float64, per band summed over texels, at thicknesses on both sides of the
    series/exp switch (z² = 0.25) and the stiff points: X = 0, 1e-7, 10 mm, S = 0, K = 0,
    K = 1e-9."""
    rng = np.random.default_rng(7)
    n = 9
    S = rng.uniform(5, 60, n)
    K = rng.uniform(0.5, 30, n)
    S[0], K[1], K[2], S[3], K[3] = 0.0, 0.0, 1e-9, 0.0, 1e-9
    q = K * (K + 2 * S)
    # thicknesses per texel: the switch z = 0.5 just below and above for band 4, stiff ones
    z_half = 0.5 / np.sqrt(q[4])
    X = np.concatenate([[0.0, 1e-7, 10.0, z_half * (1 - 1e-6), z_half * (1 + 1e-6)],
                        rng.uniform(0, 0.05, 11)])[:, None]
    S, K, X = (jnp.asarray(a, jnp.float64) for a in (S, K, X))
    aR, aT = (jnp.asarray(rng.normal(size=(X.shape[0], n))) for _ in range(2))
    dS, dK = jax.jit(lambda S, K: jax.vjp(lambda s, k: km.layer(s, k, X), S, K)[1]((aR, aT)))(
        S, K)  # (each side one program, not op by op)
    ours = jax.jit(lambda S, K: layered._layer_SK(S, K, X, km.layer_parts(S, K, X), aR, aT))
    for got, want in zip(ours(S, K), (dS, dK), strict=True):
        assert bool(jnp.all(jnp.isfinite(got)))
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-11 * float(jnp.abs(want).max()))
