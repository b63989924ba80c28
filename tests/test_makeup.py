"""Cosmetics in the render (issue 6): the spectral skin model, KM layers, SSS and per-layer
highlights, against independent forms; exactly no makeup at zero thickness; what a scene
leaves out; gradients (float64) of a whole makeup render; scene errors."""

import functools
import subprocess
import sys

import imageio.v3 as iio
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import check_grads_scaled, user_process

from jaxskin import formats, km, render, skin, spectral, sss
from jaxskin.io import InputError, data_dir
from jaxskin.mesh import Mesh
from jaxskin.projection import project
from jaxskin.scene import load_scene
from jaxskin.shading import kelemen, layered

SMALL = ["texture.size=64", "camera.size=40"]


def unit(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v)


def _flat(shape, X_values):
    N = np.zeros((*shape, 3))
    N[..., 2] = 1.0
    X = np.broadcast_to(np.asarray(X_values, np.float64).reshape(-1, *[1] * len(shape)),
                        (len(X_values), *shape)).copy()
    return N, X


@pytest.mark.parametrize("form", ["cpu", "gpu"])
def test_no_blur_is_the_exact_spectral_over_plus_highlights(x64, three_materials, form,
                                                            monkeypatch):
    """Without SSS and highlights (ρ_s = 0) a texel's colour is E · to_rgb(over(stack,
    skin)), with the stack composed here by km.compose bottom up (an independent order).
    Both forms: the CPU's chunked one and the plain one a GPU traces."""
    if form == "gpu":
        monkeypatch.setattr(layered, "_cpu_form", lambda name: False)
    grid, S, K = three_materials
    N, X = _flat((2, 3), [0.01, 0.03, 0.02])
    X[1, 0, 0] = 0.0
    skin_R = formats.nist_reflectance(12, grid)
    L, V = unit([0.3, 0.2, 1.0]), unit([0.0, 0.0, 1.0])
    out = jax.jit(lambda *a: layered.radiance(grid, *a))(  # one program, not op by op
        jnp.asarray(N), L, V, 0.25, 0.9, skin_R, 0.3, 0.0, S, K, jnp.asarray(X),
        np.full(3, 0.3), np.zeros(3))
    E = 0.25 + 0.9 * L[2]
    for i, j in np.ndindex(2, 3):
        R, T = km.layer(S, K, X[:, i, j, None])
        below = km.Slab(R[0], T[0], R[0])  # the bottom layer, then each one on top of it
        for layer in (1, 2):
            below = km.compose((R[layer], T[layer]), below)
        expected = E * np.asarray(spectral.to_rgb(km.over(below.R, below.T, skin_R,
                                                          below.R_back), grid))
        np.testing.assert_allclose(out[i, j], expected, rtol=8e-15)  # measured 8.3e-16


def test_uniform_light_and_layers_make_the_blur_a_no_op(x64, three_materials):
    """On a uniform patch the blur leaves the light alone, so the exit factor t (applied
    per XYZ channel after the blur) must give back the exact spectral result."""
    grid, S, K = three_materials
    N, X = _flat((24, 24), [0.01, 0.02, 0.03])
    args = (grid, jnp.asarray(N), unit([0.2, 0.1, 1.0]), unit([0, 0, 1.0]), 0.3, 0.8,
            formats.nist_reflectance(40, grid), 0.3, 0.18, S, K, jnp.asarray(X),
            np.full(3, 0.3), np.full(3, 0.1))
    radiance = jax.jit(layered.radiance, static_argnums=(0, 14))  # not op by op
    exact = radiance(*args, None)
    blurred = radiance(*args, lambda c: sss.blur(c, 0.5))
    np.testing.assert_allclose(blurred, exact, rtol=1e-14)  # measured 1.0e-15


@functools.partial(jax.jit, static_argnums=0)  # the three cases share its programs
def _radiance_over_bare(grid, X, S, K, skin_R, bare):
    """One texel facing the light, its blurred light the bare skin's (`bare`)."""
    N = jnp.array([[0.0, 0.0, 1.0]], X.dtype)
    return layered.radiance(grid, N, N[0], N[0], 0.3, 0.7, skin_R, 0.3, 0.0, S[None],
                            K[None], X, np.array([0.3]), np.array([0.0]),
                            blur=lambda c: jnp.broadcast_to(bare, c.shape))[0]


@pytest.mark.parametrize("name, s_scale, k_scale, X", [
    ("eyeshadow_taupe", 0.1, 10.0, 0.003), ("blush_rose", 0.1, 10.0, 0.03),
    ("blush_rose", 0.01, 50.0, 0.003)])
def test_light_from_bare_neighbours_leaves_a_strong_absorber_without_negative_light(
        x64, name, s_scale, k_scale, X):
    """At a strongly absorbing layer's edge the blurred light is the bare skin's (from the
    neighbours), not the colour of a under the layer: an exit factor per XYZ channel takes
    it out of the gamut (red −0.05, green +0.025 in the makeup scene at range values; blue
    −2e-4, −0.009, −0.026 in these cases). No channel is below 0,
    or below the texel's own light E rgb(T a) where a saturated stack makes that negative:
    the XYZ result x is moved toward y, the light dimmed by t_Y alone, by the least λ that
    lifts every channel to that floor — computed here by hand in NumPy from the spectra."""
    grid = spectral.Grid(step=10)
    mat = formats.read_material(data_dir() / "materials" / f"{name}.json")
    S = spectral.resample(mat.S, mat.wavelength_nm, grid) * s_scale
    K = spectral.resample(mat.K, mat.wavelength_nm, grid) * k_scale
    skin_R = np.asarray(formats.nist_reflectance(12, grid), np.float64)
    bare = skin_R @ grid.rgb_matrix  # E = 0.3 + 0.7 = 1 below: the bare skin's light

    def radiance(X):
        return _radiance_over_bare(grid, X, S, K, skin_R, bare)

    out = radiance(jnp.array([[X]]))
    check_grads_scaled(radiance, (jnp.array([[X]]),), (X,), order=1)
    R, T = (np.asarray(v) for v in km.layer(S, K, X))
    a = skin_R * T / (1.0 - R * skin_R)
    t = (T * a) @ grid.xyz_matrix / (a @ grid.xyz_matrix)  # per XYZ channel, in [0, 1]
    x = (bare @ np.linalg.inv(grid.xyz_to_rgb) * t) @ grid.xyz_to_rgb
    y = t[1] * bare
    floor = np.minimum((T * a) @ grid.rgb_matrix, 0.0)
    assert np.any(x < floor)  # the case: below what the texel's own light allows
    lam = max((floor[c] - x[c]) / (y[c] - x[c]) for c in range(3) if x[c] < floor[c])
    surface = R @ grid.rgb_matrix
    expected = surface + x + lam * (y - x)
    assert np.all(np.asarray(out) - surface >= floor - 1e-12), (out, floor)
    np.testing.assert_allclose(out, expected, rtol=1e-10)  # measured 7.9e-12


def test_highlights_bottom_to_top(x64, three_materials):
    """Bare skin: the skin's Kelemen highlight, white. One opaque-ish layer on top: its own
    highlight plus the skin's dimmed by the colour of T², by hand."""
    grid, S, K = three_materials
    N = np.array([[0.0, 0.0, 1.0]])
    L, V = unit([0.3, 0.0, 1.0]), unit([-0.3, 0.0, 1.0])  # mirror: the peak
    skin_R = np.zeros(len(grid)) + 1e-9  # (almost) no diffuse light: highlights only
    h_skin = float(kelemen.specular(N, L, V, 0.3, 0.18)[0])
    bare = layered.radiance(grid, jnp.asarray(N), L, V, 0.0, 1.0, skin_R, 0.3, 0.18)
    np.testing.assert_allclose(bare[0], h_skin + 0 * bare[0], atol=1e-8)  # measured 9.6e-10
    X = np.array([[0.05]])
    out = layered.radiance(grid, jnp.asarray(N), L, V, 0.0, 1.0, skin_R, 0.3, 0.18, S[2:],
                           K[2:], jnp.asarray(X), np.array([0.2]), np.array([0.3]))
    R, T = km.layer(S[2], K[2], 0.05)
    h_layer = float(kelemen.specular(N, L, V, 0.2, 0.3)[0])
    cover = 1.0  # 1 − exp(−50 µm / 1 µm): fully covered (partial cover: test_references.py)
    expected = (h_skin * np.asarray(spectral.to_rgb(T * T, grid)) + cover * h_layer
                + np.asarray(spectral.to_rgb(R, grid)) * float(N[0] @ L))
    # measured 9.3e-10: the 1e-9 skin reflectance left out of `expected`
    np.testing.assert_allclose(out[0], expected, rtol=1e-8)


ZERO_THICKNESS = """
import sys
import numpy as np
from jaxskin import render
from jaxskin.scene import load_scene
zero = [f"layer.{layer.name}.thickness_mm=0" for layer in load_scene("makeup").layers]
common = sys.argv[1:]
made_up, bare = load_scene("makeup", common + zero), load_scene("face", common)
a = np.asarray(render.render(made_up.config, made_up.params))
b = np.asarray(render.render(bare.config, bare.params))
with_makeup = load_scene("makeup", common)
print(np.array_equal(a, b),
      np.abs(np.asarray(render.render(with_makeup.config, with_makeup.params)) - b).max())
"""


@pytest.mark.parametrize("sss_on", ["true", "false"])
def test_zero_thickness_gives_exactly_the_no_makeup_image(sss_on):
    """The same bytes as a user's compiler gives them (in a process that compiles so:
    conftest's `user_process`), and makeup of its thickness far from them."""
    common = [*SMALL, f"sss.enabled={sss_on}"]
    equal, far = user_process(f"import sys\nsys.argv[1:] = {common!r}\n{ZERO_THICKNESS}").split()
    assert equal == "True"
    assert float(far) > 0.05


def test_what_a_scene_does_not_need_is_not_traced(monkeypatch):
    """No layers: no KM; sss.enabled = false: no blur. (The face's skin microstructure runs
    furrows, and none with wrinkles.enabled = false: tests/test_face_wrinkles.py.)"""
    calls = {"km": 0, "blur": 0}
    layer, blur = km.layer, sss.blur

    def counting(name, f):
        def g(*a, **k):
            calls[name] += 1
            return f(*a, **k)
        return g

    monkeypatch.setattr(km, "layer", counting("km", layer))
    monkeypatch.setattr(sss, "blur", counting("blur", blur))
    forward_km = 2 * 4 if layered._cpu_form("forward") else 1
    for name, overrides, expected in [
            ("face", [], {"km": 0, "blur": 1}),
            ("face", ["sss.enabled=false"], {"km": 0, "blur": 0}),
            # on a CPU each layer is traced twice, uniform over a chunk and varying
            # (`layered._forward_chunked`); elsewhere the stack once
            ("makeup", ["sss.enabled=false"], {"km": forward_km, "blur": 0}),
            ("makeup", [], {"km": forward_km, "blur": 1})]:
        calls.update(km=0, blur=0)
        sc = load_scene(name, [*SMALL, "camera.size=41", *overrides])  # a fresh trace
        jax.make_jaxpr(lambda p, sc=sc: render._render(sc.config, p, render.prepare(
            sc.config).arrays))(sc.params)
        assert calls == expected, (name, overrides, calls)
        assert sc.config.needs_furrows


def _float64(tree):
    return jax.tree.map(lambda a: jnp.asarray(a, jnp.float64)
                        if jnp.issubdtype(jnp.asarray(a).dtype, jnp.floating) else a, tree)


@pytest.mark.parametrize("case", ["ordinary", "extreme"])
def test_makeup_render_gradients(x64, case):
    """check_grads (float64, fwd and rev) of a whole makeup render with SSS, with respect to
    each layer's thickness, S and K scales and the skin's melanin; 'extreme': a layer at
    thickness 0, one at 5 mm (opaque), S → 0 and K → 0 scales."""
    sc = load_scene("makeup", ["texture.size=32", "camera.size=16"])
    arrays = _float64(render.prepare(sc.config).arrays)
    params = _float64(sc.params)
    if case == "ordinary":
        keys = {"layer.foundation.thickness_mm": 0.01, "layer.blush.thickness_mm": 0.02,
                "layer.lipstick.s_scale": 1.3, "layer.blush.k_scale": 0.7,
                "skin.melanin": 0.4}
    else:
        keys = {"layer.foundation.thickness_mm": 0.0, "layer.lipstick.thickness_mm": 5.0,
                "layer.blush.s_scale": 1e-9, "layer.foundation.k_scale": 1e-9,
                "skin.melanin": 0.0}
    names = list(keys)

    def f(*values):
        p = {**params, **dict(zip(names, values, strict=True))}
        return render.render_prepared(sc.config, p, arrays)

    values = [jnp.asarray(v, jnp.float64) for v in keys.values()]
    image = f(*values)
    assert bool(jnp.all(jnp.isfinite(image)))
    grads = jax.jacrev(lambda *v: jnp.sum(f(*v)), argnums=tuple(range(len(v := values))))(*v)
    assert all(bool(jnp.isfinite(g)) for g in grads)
    scales = [max(abs(float(x)), 1e-3) * 0.1 for x in keys.values()]
    check_grads_scaled(f, values, scales, order=1, eps=1e-4, atol=1e-5, rtol=1e-4)


def test_gradient_with_respect_to_a_whole_thickness_map():
    sc = load_scene("makeup", ["texture.size=32", "camera.size=16"])
    arrays = render.prepare(sc.config).arrays

    def loss(cover):
        return jnp.sum(render.render_prepared(sc.config, sc.params, {**arrays, "cover": cover}))

    g = jax.grad(loss)(arrays["cover"])
    assert g.shape == arrays["cover"].shape and bool(jnp.all(jnp.isfinite(g)))
    assert float(jnp.abs(g).max()) > 0


def test_texel_size_from_the_mesh_scale_and_uv_area():
    """A 10 × 10 square mapped onto the whole UV square at 100 texels: 0.1 units a texel;
    stretch v by 2 (a half-height UV rectangle): the mean texel is sqrt(2) × larger."""
    v = np.array([[0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0.0]])
    f = np.array([[0, 1, 2], [0, 2, 3]])
    n = np.tile([0.0, 0, 1], (4, 1))
    for uv, expected in [(v[:, :2] / 10, 0.1), (v[:, :2] / [10, 20], 0.1 * np.sqrt(2))]:
        tmap = project("uv", Mesh("square", v, f, n, uv), 100)
        assert tmap.texel_size() == pytest.approx(expected, rel=1e-12)


def test_melanin_darkens_most_in_the_blue():
    grid = spectral.Grid(10)
    base = formats.nist_reflectance(12, grid)
    assert np.array_equal(np.asarray(skin.reflectance(base.astype(np.float32), 0.0, grid)),
                          base.astype(np.float32))
    ratio = np.asarray(skin.reflectance(base, 1.0, grid)) / base
    assert np.all(np.diff(ratio) > 0) and ratio[0] < 0.2 and ratio[-1] > 0.6
    i500 = int(np.argmin(np.abs(grid.wavelengths - 500)))
    assert ratio[i500] == pytest.approx(np.exp(-1.0), rel=1e-6)  # float32


def test_nist_spectrum_is_the_subjects_mean():
    """Subject 1's mean at 400 nm, read from the CSV by hand (the 'Average' column)."""
    grid = spectral.Grid(10)
    with open(data_dir() / "spectra" / formats.NIST_FILE, encoding="latin-1") as fh:
        row = next(line for line in fh if line.startswith("400,"))
    cells = row.split(",")
    assert formats.nist_reflectance(1, grid)[2] == pytest.approx(float(cells[4]))
    assert formats.nist_reflectance(100, grid)[2] == pytest.approx(float(cells[400]))


def test_makeup_scene_renders_the_paper_figure(tmp_path):
    """The built-in makeup scene: lips red, cheeks pinker than the bare face. A 128²
    texture (the scene's is 512²: 3x the time) gives the same lips: red gain less green gain
    measured 0.340 (0.334 at 512²; with the lipstick 0 mm thick: −0.010)."""
    face, makeup = (load_scene(n, ["camera.size=128", "sss.enabled=false", "texture.size=128"])
                    for n in ("face", "makeup"))
    a = np.asarray(render.render(face.config, face.params))
    b = np.asarray(render.render(makeup.config, makeup.params))
    lips = (slice(84, 92), slice(56, 72))  # below the nose, at the lips' centre
    red_gain = b[lips][..., 0].mean() - a[lips][..., 0].mean()
    green_gain = b[lips][..., 1].mean() - a[lips][..., 1].mean()
    assert red_gain - green_gain > 0.05, (red_gain, green_gain)


@pytest.mark.parametrize("overrides,key,words", [
    (["layer.nope.thickness_mm=0.1"], "layer.nope.thickness_mm", "no layer named 'nope'"),
    (["layer.blush.colour=1"], "layer.blush.colour", "must be one of"),
    (["layer.blush.thickness_mm=-1"], "layer.blush.thickness_mm", "must be in"),
    (["material.model=blinn"], "layer", "need material.model"),
])
def test_bad_layer_overrides_name_the_key(overrides, key, words):
    with pytest.raises(InputError) as e:
        load_scene("makeup", overrides)
    assert e.value.key == key and words in str(e.value)


@pytest.mark.parametrize("text,key,words", [
    ('[[layer]]\nname = "a"\nmaterial = "no_such"\n', "layer.a.material", "shipped"),
    ('[[layer]]\nname = "a b"\nmaterial = "blush_rose"\n', "layer[0].name", "letters"),
    ('[[layer]]\nname = "a"\nmaterial = "blush_rose"\nthikness_mm = 1\n', "layer[0].thikness_mm",
     "did you mean 'thickness_mm'"),
    ('[[layer]]\nname = "a"\nmaterial = "blush_rose"\n[[layer.ellipse]]\ncenter = [0.5]\n',
     "layer.a.ellipse[0].center", "2 finite numbers"),
    ('[[layer]]\nname = "a"\nmaterial = "blush_rose"\n[[layer.polygon]]\nfeather = 0.1\n',
     "layer.a.polygon[0]", "exactly one of"),
    ('[[layer]]\nname = "a"\nmaterial = "blush_rose"\n[[layer]]\nname = "a"\n'
     'material = "blush_rose"\n', "layer.name", "two layers"),
])
def test_bad_layer_tables_name_the_key(tmp_path, text, key, words):
    path = tmp_path / "s.toml"
    path.write_text('[material]\nmodel = "spectral"\n' + text)
    with pytest.raises(InputError) as e:
        load_scene(path)
    assert e.value.key == key and words in str(e.value), str(e.value)


def test_region_from_an_image_and_from_vertices(tmp_path):
    img = np.zeros((8, 8), np.uint8)
    img[:4] = 255  # the top half: v > 0.5
    iio.imwrite(tmp_path / "map.png", img)
    (tmp_path / "s.toml").write_text(
        '[mesh]\nfile = "face"\nprojection = "uv"\n[texture]\nsize = 32\n[material]\n'
        'model = "spectral"\n[wrinkles]\nenabled = false\n'
        '[[layer]]\nname = "top"\nmaterial = "blush_rose"\nimage = "map.png"\n'
        '[[layer]]\nname = "tri"\nmaterial = "blush_rose"\n[[layer.polygon]]\n'
        'vertices = [61, 291, 1]\n')
    sc = load_scene(tmp_path / "s.toml")
    p = render.prepare(sc.config)
    cover = np.zeros((2, 32 * 32))
    cover[:, np.asarray(p.arrays["texels"])] = np.asarray(p.arrays["cover"])
    top, tri = cover.reshape(2, 32, 32)
    mask = np.asarray(p.setup.mask)
    assert np.all(top[:16][mask[:16]] == 1) and np.all(top[16:] == 0)
    uv = p.setup.tmap.mesh.uv[[61, 291, 1]]  # the mouth corners and the nose tip
    row = int((1 - uv[:, 1].mean()) * 32)
    col = int(uv[:, 0].mean() * 32)
    assert tri[row, col] == 1 and tri[2, 2] == 0


def test_render_command_sweeps_a_layer(tmp_path):
    r = subprocess.run([sys.executable, "-m", "jaxskin.cli", "render", "makeup", "-o",
                        str(tmp_path), "-D", "texture.size=64", "-D", "camera.size=32",
                        "--sweep", "layer.lipstick.thickness_mm=0:0.05:3"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    names = sorted(p.name for p in tmp_path.glob("*.png"))
    assert names == [f"makeup_texture.size-64_camera.size-32_sweep-{i:02d}_layer.lipstick."
                     f"thickness_mm-{v}.png" for i, v in ((1, "0"), (2, "0.025"), (3, "0.05"))]
    r = subprocess.run([sys.executable, "-m", "jaxskin.cli", "render", "makeup", "-o",
                        str(tmp_path / "x"), "-D", "layer.lips.thickness_mm=1"],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "no layer named 'lips'" in r.stderr
    assert "Traceback" not in r.stderr and not (tmp_path / "x").exists()


def test_glb_albedo_of_the_makeup_is_the_layers_over_the_skin(tmp_path):
    """The export's base colour: red on the lips, the bare skin's colour where no layer
    lies (a face scene gives the same texels), and an ordinary .glb from the CLI."""
    made_up, bare = (load_scene(n, ["texture.size=64", "camera.size=16"]) for n in
                     ("makeup", "face"))
    a = np.asarray(render.albedo(made_up.config, made_up.params))
    b = np.asarray(render.albedo(bare.config, bare.params))
    uv = render.prepare(made_up.config).setup.tmap.mesh.uv[[0, 17]].mean(axis=0)  # the lips
    r, c = int((1 - uv[1]) * 64), int(uv[0] * 64)
    assert a[r, c, 0] - a[r, c, 1] > b[r, c, 0] - b[r, c, 1] + 0.1
    r = subprocess.run([sys.executable, "-m", "jaxskin.cli", "render", "makeup", "-o",
                        str(tmp_path), "-D", "texture.size=64", "-D", "camera.size=16", "--glb"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "makeup_texture.size-64_camera.size-16.glb").stat().st_size > 1000


def test_the_spectral_render_bakes_no_large_constant():
    """The SSS kernels are an argument of the compiled render, not a constant: the spectral
    hand at its old scale (1 mm per mesh unit: 0.03 mm texels at 64²) once baked a 3 x 1137 x 1137 kernel into its program (31 MB
    of StableHLO; 3 x 9083² floats, 2 GB, at the default 512², with XLA's "constant folding
    pad" warning), padded at compile time to a 1200² FFT for a 64² texture."""
    import re

    scene = load_scene("hand", ["material.model=spectral", "texture.size=64", "camera.size=32",
                                "wrinkles.enabled=false", "mesh.unit_mm=1"])
    arrays = render.prepare(scene.config).arrays
    assert arrays["sss_kernels"].shape == (3, 127, 127)  # cut to what 64² reaches
    text = render._render.lower(scene.config, scene.params, arrays, "display").as_text()
    sizes = [np.prod([int(d) for d in shape.split("x")[:-1]], dtype=np.int64)
             for shape in re.findall(r"stablehlo\.constant dense<.*?> : tensor<([^>]*)>", text)]
    assert max(sizes, default=0) <= 1024 and len(text) < 500_000, (max(sizes), len(text))
