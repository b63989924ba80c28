"""Shading (Blinn, Lafortune) and the render: analytic checks, gradients at grazing light
and huge exponents, what a scene leaves out, sweeps."""

import re
import subprocess
import sys

import imageio.v3 as iio
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import check_grads_scaled

from jaxskin import render, render_args, texture, wrinkles
from jaxskin.scene import load_scene
from jaxskin.shading import blinn, lafortune


def unit(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v)


def test_blinn_flat_plane_by_hand():
    """Light = view = (0, 0, 1) on a flat plane: cos θ = cos γ = 1, so by eq. 4.12 with the
    paper's defaults c = 0.3 r + 0.7 r + 0.7 × 0.2 = r + 0.14 (r, the skin albedo, is
    checked on its own in tests/test_skin_colour.py)."""
    z = np.array([0.0, 0.0, 1.0])
    c = blinn.shade(z, z, z, 0.2, 0.5, 0.2, 100.0)
    r = np.asarray(blinn.skin_colour(0.2, 0.5))
    np.testing.assert_allclose(c, r + 0.14, rtol=1e-6)
    # Light from the side (60°): cos θ = 0.5, H halfway: cos γ = cos 30°.
    L = unit([np.sin(np.pi / 3), 0, 0.5])
    c = blinn.shade(z, L, z, 0.2, 0.5, 0.2, 100.0)
    np.testing.assert_allclose(c, 0.3 * r + 0.7 * r * 0.5 + 0.7 * 0.2 * np.cos(np.pi / 6) ** 100,
                               rtol=1e-5)
    # Light behind the surface: ambient only, no highlight.
    np.testing.assert_allclose(blinn.shade(z, -z, z, 0.2, 0.5, 0.2, 100.0), 0.3 * r, rtol=1e-6)


def test_lafortune_shade_matches_the_brdf_in_the_local_frame(x64):
    p = lafortune.skin(jnp.float64)
    N, L, V = unit([0.1, 0.2, 0.97]), unit([0.5, -0.3, 0.8]), unit([-0.4, 0.1, 0.9])
    # An explicit local frame around N.
    t = unit(np.cross(N, [1.0, 0, 0]))
    b = np.cross(N, t)
    local = lambda w: np.array([w @ t, w @ b, w @ N])  # noqa: E731
    f = lafortune.brdf(p, local(L), local(V))
    # Eq. 4.16 on Blinn's scale: π f, so that f = ρd/π gives ρd cos θ (shading.lafortune).
    expected = 0.3 * np.asarray(p.diffuse) + np.pi * 0.7 * np.asarray(f) * (N @ L)
    np.testing.assert_allclose(lafortune.shade(p, N, L, V), expected, rtol=1e-12)


POINTS = {
    "ordinary": (unit([0.1, 0.2, 0.97]), unit([0.5, -0.3, 0.8]), 100.0),
    "grazing light": (unit([0.0, 0.0, 1.0]), unit([1.0, 0.0, 1e-5]), 100.0),
    "n_z -> 0": (unit([1.0, 0.2, 1e-7]), unit([0.6, 0.1, 0.8]), 100.0),
    "huge shininess": (unit([0.0, 0.05, 1.0]), unit([0.0, -0.05, 1.0]), 1e4),
}


# Jitted once for the module (N and V arguments, not constants): check_grads' programs
# compile once for all the points instead of op by op (the checks are the same).
_blinn = jax.jit(lambda N, V, m, b, s, sh, l_: blinn.shade(N, l_, V, m, b, s, sh))


@jax.jit
def _lafortune(diffuse, N, V, Cxy, Cz, n, l_):
    return lafortune.shade(lafortune.Lafortune(diffuse, Cxy, Cz, n), N, l_, V)


@pytest.mark.parametrize("name", POINTS)
def test_blinn_gradients(x64, name):
    N, L, n = POINTS[name]
    V = np.array([0.0, 0.0, 1.0])
    check_grads_scaled(lambda m, b, s, sh, l_: _blinn(N, V, m, b, s, sh, l_),
                       [0.2, 0.5, 0.2, n, L], [0.05, 0.05, 0.05, n / 100, 1e-3], eps=1e-4)


@pytest.mark.parametrize("name", ["ordinary", "grazing light", "n_z -> 0"])
def test_lafortune_shade_gradients(x64, name):
    N, L, _ = POINTS[name]
    V = unit([0.1, 0.0, 1.0])
    p = lafortune.skin(jnp.float64)

    def f(Cxy, Cz, n, l_):
        return _lafortune(p.diffuse, N, V, Cxy, Cz, n, l_)

    check_grads_scaled(f, [p.Cxy, p.Cz, p.n, L], [0.05, 0.05, 1.0, 1e-3], eps=1e-4)


@pytest.fixture(scope="module")
def small_hand():
    return load_scene("hand", ["texture.size=96", "camera.size=48"])


def test_render_gradients_wrt_material_light_and_bump(small_hand):
    config, params = small_hand.config, small_hand.params
    keys = ["material.melanin", "material.blood", "material.specular", "material.shininess",
            "wrinkles.k_bump", "light.direction"]

    def loss(sub):
        image = render.render(config, {**params, **sub})
        return jnp.mean((image - 0.5) ** 2)

    sub = {k: params[k] for k in keys}
    grads = jax.grad(loss)(sub)
    for k in keys:
        assert bool(jnp.all(jnp.isfinite(grads[k]))) and float(jnp.abs(grads[k]).sum()) > 0, k
    # Gradient against central differences in melanin (float32 render): measured 4.2e-6
    # with eq. 5.7's colours, 3.5e-4 with the sRGB-encoded renders of branch `look`.
    h = 1e-2
    plus = loss({**sub, "material.melanin": sub["material.melanin"] + h})
    minus = loss({**sub, "material.melanin": sub["material.melanin"] - h})
    np.testing.assert_allclose(grads["material.melanin"], (plus - minus) / (2 * h), rtol=4e-3)


def test_view_sampling_gradient(x64):
    """The view is linear in the texture-space image: check_grads through the sampler."""
    from jaxskin.view import sample

    tex = jnp.asarray(np.random.default_rng(0).uniform(1, 7, (5, 6, 2)))
    mask = jnp.ones((5, 6), bool).at[0, 0].set(False)
    image = jnp.asarray(np.random.default_rng(1).uniform(0, 1, (8, 8, 3)))
    check_grads_scaled(jax.jit(lambda im: sample(im, tex, mask, True)), [image], [1.0],
                       order=2)


def test_a_blinn_scene_traces_no_lafortune_and_the_overview_no_furrows(small_hand, monkeypatch):
    config, params = small_hand.config, small_hand.params
    assert "material.lafortune" not in params
    jaxpr = str(jax.make_jaxpr(lambda p: render._render(config, p, render.prepare(
        config).arrays))(params))
    assert "log" in jaxpr  # the Blinn highlight's power
    lf = load_scene("hand", ["texture.size=96", "camera.size=48", "material.model=lafortune"])
    assert "material.melanin" not in lf.params and "material.lafortune" in lf.params
    calls = []
    monkeypatch.setattr(wrinkles, "height_field", lambda *a, **k: calls.append(1))
    texture.furrows.cache_clear()
    render.prepare.cache_clear()
    overview = load_scene("hand", ["texture.size=96", "camera.size=48", "view.mode=overview"])
    image = render.render(overview.config, overview.params)
    assert calls == [] and image.shape == (48, 48, 3)
    texture.furrows.cache_clear()
    render.prepare.cache_clear()


def test_overview_has_no_wrinkles_and_wrinkles_mode_does(small_hand):
    config, params = small_hand.config, small_hand.params
    wrinkled = np.asarray(render.render(config, params))
    overview = load_scene("hand", ["texture.size=96", "camera.size=48", "view.mode=overview"])
    smooth = np.asarray(render.render(overview.config, overview.params))
    on = wrinkled.sum(-1) > 0
    assert np.mean(np.abs(wrinkled - smooth)[on]) > 1e-3
    flat = load_scene("hand", ["texture.size=96", "camera.size=48", "wrinkles.k_bump=0"])
    np.testing.assert_allclose(np.asarray(render.render(flat.config, flat.params)), smooth,
                               atol=1e-5)


def test_render_command_with_a_vmapped_sweep(tmp_path):
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "jaxskin.cli", "render", "foot", "-o", str(out),
                           "-D", "texture.size=64", "-D", "camera.size=32", "--sweep",
                           "material.melanin=0:1:3"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    names = [f"foot_texture.size-64_camera.size-32_sweep-{i:02d}_material.melanin-{v}.png"
             for i, v in ((1, "0"), (2, "0.5"), (3, "1"))]
    assert sorted(p.name for p in out.iterdir()) == names  # sorted = sweep order
    assert all(str(out / n) in proc.stdout for n in names)  # the run reports every file
    images = [iio.imread(out / n) for n in names]
    means = [im[im.sum(-1) > 0].mean() for im in images]
    assert means[0] > means[1] > means[2]  # more melanin, darker skin
    bad = subprocess.run([sys.executable, "-m", "jaxskin.cli", "render", "foot", "-o", str(out),
                          "--sweep", "camera.size=1:2:2"], capture_output=True, text=True)
    assert bad.returncode == 2 and "not a scalar parameter" in bad.stderr


def test_a_sweep_over_a_key_one_scene_lacks_renders_that_scene_once(tmp_path):
    """`render hand face --sweep material.shininess=…` must not stop the whole command on
    the face (spectral: no shininess), where -D warns and renders. The face is rendered
    once, with a warning naming it; a key no scene has is still an error."""
    out = tmp_path / "out"
    small = ["-D", "texture.size=64", "-D", "camera.size=32"]
    proc = subprocess.run([sys.executable, "-m", "jaxskin.cli", "render", "hand", "face", "-o",
                           str(out), *small, "--sweep", "material.shininess=20:40:2"],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert ("jaxskin: warning: --sweep material.shininess=20:40:2 changes nothing in scene "
            "'face' (not one of its parameters): it is rendered once, unswept") in proc.stderr
    assert sorted(p.name for p in out.iterdir()) == [
        "face_texture.size-64_camera.size-32.png",
        "hand_texture.size-64_camera.size-32_sweep-01_material.shininess-20.png",
        "hand_texture.size-64_camera.size-32_sweep-02_material.shininess-40.png"]
    a, b = (iio.imread(out / f"hand_texture.size-64_camera.size-32_sweep-0{i}_material."
                       f"shininess-{v}.png") for i, v in ((1, 20), (2, 40)))
    assert not np.array_equal(a, b)  # the hand's sweep did sweep
    bad = subprocess.run([sys.executable, "-m", "jaxskin.cli", "render", "hand", "face", "-o",
                          str(tmp_path / "bad"), "--sweep", "material.shinines=20:40:2"],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "did you mean 'material.shininess'" in bad.stderr
    assert not (tmp_path / "bad").exists()



def test_a_key_of_the_other_skin_model_is_warned_with_the_key_the_scene_reads(tmp_path):
    """`-D skin.melanin=0.3` on the Blinn hand and `--sweep material.melanin` on the
    spectral face (natural first guesses): each warning names the key that scene reads."""
    out = tmp_path / "out"
    small = ["-D", "texture.size=64", "-D", "camera.size=32"]
    proc = subprocess.run([sys.executable, "-m", "jaxskin.cli", "render", "hand", "face", "-o",
                           str(out), *small, "-D", "skin.melanin=0.3", "--sweep",
                           "material.melanin=0.1:0.4:2"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert ("-D skin.melanin=0.3 changes nothing in scene 'hand' (its material model or "
            "settings do not use it; it reads material.melanin)") in proc.stderr
    assert ("--sweep material.melanin=0.1:0.4:2 changes nothing in scene 'face' (not one of "
            "its parameters; it reads skin.melanin): it is rendered once") in proc.stderr

def test_glb_export_reloads_with_textures(tmp_path):
    import trimesh

    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "jaxskin.cli", "render", "arm", "-o", str(out),
                           "--glb", "-D", "texture.size=128", "-D", "camera.size=32"],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    glb = out / "arm_texture.size-128_camera.size-32.glb"
    scene = trimesh.load(glb)
    mesh = next(iter(scene.geometry.values()))
    normal = np.asarray(mesh.visual.material.normalTexture)[..., :3] / 255.0 * 2 - 1
    # One vertex per (mesh vertex, UV): the seam's vertices split, no others.
    assert len(mesh.faces) / 2 < len(mesh.visual.uv) < 3 * len(mesh.faces) / 2
    # Tangent space: mostly facing out (+z), tilted by the wrinkles.
    assert np.median(normal[..., 2]) > 0.9 and np.std(normal[..., 0]) > 1e-3
    assert glb.stat().st_mode & 0o044  # readable like any written file


def test_output_files_get_ordinary_permissions(tmp_path):
    from jaxskin.io import atomic_write

    with atomic_write(tmp_path / "x.txt", "w") as fh:
        fh.write("x")
    import os

    mask = os.umask(0)
    os.umask(mask)
    assert (tmp_path / "x.txt").stat().st_mode & 0o777 == 0o666 & ~mask


def test_perspective_and_supersampling_render():
    """Perspective renders; 2×2 supersampling gives edge pixels partial coverage: darker
    than any covered pixel of the aliased render (ambient alone is ~0.3 r), in linear light
    (the images are sRGB-encoded)."""
    base = ["texture.size=96", "camera.size=40", "camera.projection=perspective",
            "camera.rotate=[20.0, 0.0, 0.0]"]
    images = {}
    for k in (1, 2):
        sc = load_scene("foot", [*base, f"camera.supersample={k}"])
        display = np.asarray(render.render(sc.config, sc.params), np.float64)
        assert display.shape == (40, 40, 3) and np.all(np.isfinite(display))
        images[k] = np.where(display > 0.04045, ((display + 0.055) / 1.055) ** 2.4,
                             display / 12.92)
    covered = images[1].sum(-1) > 0
    assert 0.05 < covered.mean() < 0.9
    darkest_aliased = images[1].sum(-1)[covered].min()
    soft = images[2].sum(-1)
    assert np.sum((soft > 0) & (soft < 0.5 * darkest_aliased)) > 5


def test_height_mode_shows_the_height_field():
    sc = load_scene("hand", ["texture.size=96", "camera.size=48", "view.mode=height"])
    image = np.asarray(render.render(sc.config, sc.params))
    on = image.sum(-1) > 0
    np.testing.assert_allclose(image[..., 0], image[..., 1])
    assert image[on, 0].min() < 0.9 and image[on, 0].max() <= 1.0 + 1e-6


def test_two_sweeps_are_refused_before_anything_is_written(tmp_path):
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "jaxskin.cli", "render", "foot", "arm", "-o",
                           str(out), "-D", "texture.size=32", "-D", "camera.size=16",
                           "--sweep", "material.melanin=0:1:2", "--sweep",
                           "material.blood=0:1:2"], capture_output=True, text=True)
    assert proc.returncode == 2 and "one --sweep at a time" in proc.stderr
    assert not out.exists()


def test_a_first_render_inside_jit_leaves_no_tracer_in_the_cache():
    """`prepare` first asked for inside a trace (the README's fitting pattern under `jit`)
    must cache concrete arrays: before the fix, the next call raised UnexpectedTracerError."""
    for method in ("sequential", "parallel"):  # the furrow programs run inside it too
        render.prepare.cache_clear()
        texture.setup.cache_clear()
        texture.furrows.cache_clear()
        sc = load_scene("hand", ["texture.size=64", "camera.size=32",
                                 f"wrinkles.method={method}"])
        assert not render._tracing()
        inside = jax.jit(lambda p, c=sc.config: (_assert_tracing(), render.render(c, p))[1])(
            sc.params)
        outside = render.render(sc.config, sc.params)
        # One float32 ulp apart (max 1.5e-7): XLA fuses the nested jit differently.
        np.testing.assert_allclose(np.asarray(inside), np.asarray(outside), rtol=0, atol=1e-6)
    render.prepare.cache_clear()
    texture.furrows.cache_clear()


def _assert_tracing():
    assert render._tracing()


def test_scene_params_first_read_inside_jit_are_concrete():
    """`Scene.params` is cached on first read; read first inside a jit, jnp.asarray of
    `light.direction`'s list was a tracer, kept in the cache, and the next use raised
    UnexpectedTracerError (found when the stability sweep was jitted)."""
    sc = load_scene("makeup", ["texture.size=32", "camera.size=16"])
    arrays = render.prepare(sc.config).arrays
    jax.jit(lambda t: render.render_prepared(
        sc.config, {**sc.params, "layer.blush.thickness_mm": t}, arrays))(jnp.float32(0.02))
    assert not any(isinstance(v, jax.core.Tracer) for v in sc.params.values())
    assert render.render(sc.config, sc.params).shape == (16, 16, 3)


def test_a_sweep_frame_does_not_depend_on_the_sweep_around_it():
    """A value's frame is the same float32 image whether the sweep has 1 value or 3: every
    batch has `batch.SWEEP_BATCH` values (padded), one compiled program. (Batches of 1
    and 3 once differed by 1.6e-4 in display values, the makeup over skin.melanin on 2
    CPU cores: XLA rounds each batch size's program differently.) A single render, not
    vmapped, is a program of its own: it is bounded here, not equal (measured 1.6e-4 at
    128², about 1/25 of an 8-bit step)."""
    from jaxskin import batch

    scene = load_scene("makeup", ["texture.size=64", "camera.size=32"])
    params = jax.tree.map(np.asarray, scene.params)

    def frames(values):
        batches = batch.sweep_batches(values)
        assert all(len(b) == batch.SWEEP_BATCH for b in batches)
        return np.concatenate([batch.render_batch((scene.config, params, "skin.melanin", b,
                                                     "display")) for b in batches])

    alone, among = frames([2.0])[0], frames([0.0, 1.0, 2.0])[2]
    np.testing.assert_array_equal(alone, among)
    single = np.asarray(render.render(scene.config, {**scene.params, "skin.melanin": 2.0}))
    assert np.abs(single - among).max() < 5e-4


def test_render_refuses_what_it_would_otherwise_render_wrong():
    """A map of another size would be read at clamped indices (the blush on the wrong
    texels, no error); a misspelt key ignored (its gradient exactly 0); a Scene for its
    config fail with "'Scene' object has no attribute 'shadow'". Each is refused."""
    import jax.numpy as jnp

    s = load_scene("makeup", ["texture.size=32", "camera.size=16"])
    arrays = render.prepare(s.config).arrays
    with pytest.raises(ValueError, match=r"'layer.blush.map'\]: expected a texture-space map "
                                         r"of shape \(32, 32\).*got \(64, 64\)"):
        render.render_prepared(s.config, s.params | {"layer.blush.map": jnp.ones((64, 64))},
                               arrays)
    with pytest.raises(ValueError, match=r"unknown key 'layer.blsh.map' \(did you mean "
                                         r"'layer.blush.map'\?\)"):
        render.render(s.config, s.params | {"layer.blsh.map": jnp.ones((32, 32))})
    with pytest.raises(ValueError, match="unknown key 'material.melannin'"):
        render.render(s.config, s.params | {"material.melannin": 0.3})
    with pytest.raises(TypeError, match=r"expected a SceneConfig \(pass scene.config\), got "
                                        "Scene"):
        render.render(s, s.params)
    # a key that is known but unused by this model is no error (one dict, several scenes)
    render.render(s.config, s.params | {"material.melanin": 0.3})
    # a scalar of another shape (several values at once) failed deep inside, "Incompatible
    # shapes for broadcasting"; under vmap each call sees one value and renders
    for key, value, what in (("layer.blush.thickness_mm", jnp.ones(2), "a number (shape ())"),
                             ("light.direction", jnp.ones(2), "a 3-vector (shape (3,))"),
                             ("camera.exposure", jnp.ones((1, 1)), "a number (shape ())")):
        with pytest.raises(ValueError, match=rf"params\['{key}'\]: expected {re.escape(what)}, "
                                             rf"got shape \({value.shape[0]},"):
            render.render(s.config, s.params | {key: value})
    images = jax.vmap(lambda t: render.render(
        s.config, s.params | {"layer.blush.thickness_mm": t}))(jnp.asarray([0.0, 0.02]))
    assert images.shape == (2, 16, 16, 3) and float(jnp.abs(images[1] - images[0]).max()) > 0


def test_python_numbers_as_params_reuse_the_compiled_render(x64):
    """A Python float in params traces as a weakly typed value: every new one would compile
    `_render` again (0.7-0.8 s on the 32² hand). Numbers become
    arrays of the other params' dtype: float32 scene params keep a float32 image, float64
    ones (under x64) a float64 image, and new values reuse the program. (The hand at the
    size test_render_checks_missing_keys_... renders it: the programs are compiled once.)"""
    s = load_scene("hand", ["texture.size=32", "camera.size=16"])
    first = render.render(s.config, s.params)
    assert first.dtype == jnp.float32
    size = render._render._cache_size()
    for value in (0.45, 0.5, 1):
        image = render.render(s.config, {**s.params, "material.melanin": value})
        assert image.dtype == jnp.float32
    assert render._render._cache_size() == size
    p64 = {k: jnp.asarray(v, jnp.float64) for k, v in s.params.items()}
    assert render.render(s.config, {**p64, "material.melanin": 0.45}).dtype == jnp.float64
    a = render.render(s.config, {**s.params, "material.melanin": 0.45})
    b = render.render(s.config, {**s.params, "material.melanin": jnp.float32(0.45)})
    assert bool(jnp.all(a == b))


def test_render_checks_missing_keys_ranges_lists_and_mixed_dtypes(x64):
    """Through the Python API: a missing key is not a bare KeyError from deep inside;
    out-of-range values would render unphysical pixels without a word (a negative
    thickness: −2e19); a list for light.direction would fail in jnp.linalg.norm; one float64
    value among float32 ones would crash the makeup scene in lax.switch (mismatched branch
    types) while the hand promoted. Each is now an error naming the key, or works."""
    s = load_scene("makeup", ["texture.size=32", "camera.size=16"])
    h = load_scene("hand", ["texture.size=32", "camera.size=16"])
    without = {k: v for k, v in h.params.items() if k != "material.melanin"}
    with pytest.raises(ValueError, match=r"^params: missing key 'material.melanin'; .*"
                                         r"start from it, e.g. scene.params \| \{key: value\}"):
        render.render(h.config, without)
    with pytest.raises(ValueError, match=r"^params: missing keys 'skin.melanin', "
                                         r"'skin.roughness', .* and \d+ more"):
        render.render(s.config, h.params)
    for sc, key, value, words in (
            (s, "layer.blush.thickness_mm", -0.05, r"must be in \[0, 10\] .*got -0.05$"),
            (h, "light.intensity", -1.0, r"must be in \[0, 10\]"),
            (h, "material.melanin", float("nan"), r"must be in \[0, 1\] .*got nan"),
            (h, "light.direction", [0.0, 0.0, 0.0], "expected a finite, non-zero 3-vector")):
        with pytest.raises(ValueError, match=rf"^params\['{re.escape(key)}'\]: {words}"):
            render.render(sc.config, sc.params | {key: jnp.asarray(value, jnp.float32)})
    for value in (True, np.bool_(False)):  # not True rendered as 1.0
        with pytest.raises(ValueError, match=r"^params\['material.melanin'\]: expected a "
                                             r"number, got (True|False)$"):
            render.render(h.config, h.params | {"material.melanin": value})
    # at the ends of the range, and traced (unchecked): renders
    render.render(s.config, s.params | {"layer.blush.thickness_mm": 0.0})
    g = jax.grad(lambda t: render.render(s.config, s.params | {
        "layer.blush.thickness_mm": t}).sum())(jnp.float32(0.02))
    assert np.isfinite(float(g))
    listed = render.render(h.config, h.params | {"light.direction": [0.0, 0.0, 1.0]})
    assert bool(jnp.all(listed == render.render(h.config, h.params)))
    for key in ("light.intensity", "skin.melanin", "camera.exposure"):
        image = render.render(s.config, s.params | {key: jnp.asarray(s.params[key],
                                                                     jnp.float64)})
        assert image.dtype == jnp.float64, key
        assert float(jnp.abs(image - render.render(s.config, s.params)).max()) < 1e-5, key


def test_every_range_end_passes_the_range_check_in_float32():
    """`render`'s range check must not compare a float32 value with the float64 bound:
    float32(0.1) is above 0.1, so a scene at six documented range ends (skin.haemoglobin =
    0.1, skin.roughness = 0.01, ...) would fail to render. Every scalar key
    at both of its ends, as float32 and float64, passes; just outside them fails."""
    configs = [load_scene(name, ["texture.size=32", "camera.size=16", *more]).config
               for name, more in (("makeup", []), ("face", ["material.model=biophysical"]),
                                  ("hand", []))]
    specs = {k: s for c in configs for k, s in render_args.known_keys(c)[0].items()
             if s is not None and s.kind is float}
    assert {"skin.haemoglobin", "layer.blush.roughness", "material.melanin"} <= set(specs)
    for key, spec in specs.items():
        for end in (spec.lo, spec.hi):
            for dtype in (np.float32, np.float64):
                render_args.check_ranges({key: np.asarray(end, dtype)}, specs)
        for outside in (spec.lo - abs(spec.lo) * 1e-3 - 1e-3, spec.hi + abs(spec.hi) * 1e-3):
            with pytest.raises(ValueError, match="the scene key's range"):
                render_args.check_ranges({key: np.float32(outside)}, specs)
    s = load_scene("face", ["texture.size=32", "camera.size=16", "material.model=biophysical",
                            "skin.haemoglobin=0.1", "skin.epidermis_mm=0.01"])
    assert np.isfinite(np.asarray(render.render(s.config, s.params))).all()
