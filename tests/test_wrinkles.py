"""The furrow height field: the paper's three observations, measured; determinism; the
NumPy transcription agrees; bump normals gradient-checked, stable as n_z -> 0."""

import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import check_grads_scaled

from jaxskin import bump, texture, wrinkles
from jaxskin.scene import load_scene

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
import numpy_furrows  # noqa: E402  (the baseline transcription)


def uniform_fields(n, angle1_deg, mag1, angle2_deg, mag2):
    """Uniform fields in the pixel frame (x right, y down), angles counter-clockwise on screen."""
    def f(a, m):
        a = np.radians(a)
        return np.broadcast_to(np.array([np.cos(a), -np.sin(a)], np.float32) * m, (n, n, 2))
    return f(angle1_deg, mag1), f(angle2_deg, mag2)


def run(mask, f1, f2, k_scale=1.0, seed=0, records=4096):
    centroids = jnp.asarray([[mask.shape[1] / 2, mask.shape[0] / 2]], jnp.float32)
    h, rec = wrinkles.height_field(jnp.asarray(mask), jnp.asarray(f1), jnp.asarray(f2),
                                   centroids, k_scale, jax.random.key(seed),
                                   radius=wrinkles.window_radius(k_scale), records=records)
    return np.asarray(h), wrinkles.to_numpy_record(rec, records)


def line_orientations(h, box=7):
    """Structure tensor: per texel, the orientation (deg, mod 180, screen frame) of the
    lines, and a weight (energy × coherence). The height is smoothed first (the usual
    inner scale), or one-texel lines read as their pixel staircases."""

    def smooth(a, b=box):
        c = np.cumsum(np.cumsum(np.pad(a, ((b, 0), (b, 0))), 0), 1)
        return (c[b:, b:] - c[:-b, b:] - c[b:, :-b] + c[:-b, :-b]) / (b * b)

    gy, gx = np.gradient(smooth(smooth(h.astype(np.float64), 3), 3))
    gy = -gy  # screen frame: y up
    jxx, jyy, jxy = smooth(gx * gx), smooth(gy * gy), smooth(gx * gy)
    gradient_dir = 0.5 * np.degrees(np.arctan2(2 * jxy, jxx - jyy))
    coherence = np.hypot(jxx - jyy, 2 * jxy)
    return np.mod(gradient_dir + 90.0, 180.0), coherence


def peak_near(angles, weights, expected, others, window=20.0):
    """The histogram's highest bin within ±window of `expected` (deg), and its prominence:
    its height over the background (the mean of the bins over 25° from every field)."""
    hist, edges = np.histogram(angles, bins=90, range=(0, 180), weights=weights)
    centres = edges[:-1] + 1.0

    def gap(a):
        return np.abs((centres - a + 90) % 180 - 90)

    best = int(np.argmax(np.where(gap(expected) <= window, hist, -1)))
    background = np.all([gap(a) > 25 for a in others], axis=0)
    return centres[best], hist[best] / hist[background].mean()


def angle_gap(a, b):
    return abs((a - b + 90) % 180 - 90)


@pytest.mark.parametrize("a1, a2", [(30, 110), (0, 90), (45, 135), (75, 160), (10, 60)])
def test_furrows_run_along_the_fields(a1, a2):
    """Each family's structure-tensor orientation histogram peaks within 10° of its field.

    The height map is the minimum of the two passes' images; each pass's furrows are the
    texels its furrows drew (the pass's owner image), so each family is measured on its own.
    (On the merged map the lattice mixes the two inside any window that resolves
    orientation, pulling the peaks together; at k_scale 1 the diamonds are ~4 texels.)"""
    n = 192
    f1, f2 = uniform_fields(n, a1, 1.0, a2, 1.0)
    _, rec = run(np.ones((n, n), bool), f1, f2)
    for p, expected in enumerate((a1, a2)):
        furrows = (rec[p]["owner"] >= 0).astype(float)
        angles, weights = line_orientations(furrows, box=5)
        angles, weights = angles[8:-8, 8:-8].ravel(), weights[8:-8, 8:-8].ravel()
        peak, prominence = peak_near(angles, weights, expected, (expected,))
        assert angle_gap(peak, expected) < 10, (expected, peak)
        assert prominence > 3, (expected, prominence)


def test_crossing_furrows_end_on_each_other():
    """Of the furrow ends (not at the mesh border) that touch another furrow of the same
    pass, most stopped on it: T-junctions. Measured on the hand: 97 % and 100 %."""
    sc = load_scene("hand", ["texture.size=256"])
    _, rec = texture.furrows(sc.config.texture)
    rec = wrinkles.to_numpy_record(rec, texture.RECORDS)
    for p in range(2):
        r = rec[p]
        met = stopped = 0
        for fid in range(len(r["reason"])):
            for half in range(2):
                reason = r["reason"][fid, half]
                if reason == wrinkles.END_BORDER:
                    continue
                ix, iy = (int(np.floor(c)) for c in r["end"][fid, half])
                around = r["owner"][max(iy - 1, 0):iy + 2, max(ix - 1, 0):ix + 2]
                if np.any((around >= 0) & (around != fid)):
                    met += 1
                    stopped += reason == wrinkles.END_FURROW
        assert met > 50
        assert stopped / met > 0.9, (p, stopped, met)


def test_larger_magnitude_gives_longer_sparser_wider_deeper_furrows():
    """The paper's "straighter, longer, sparser, wider, deeper" follows its functions in
    order (f_angle, f_length, f_density, f_width, f_depth): "longer" is the segment length.
    The total length of a furrow is not monotone: f_limit = ⌊30 − 10x⌋ shortens furrows as
    |d| grows (measured mean total 24, 47, 61, 55 texels for |d| = 0.5 … 2). 128² (2026-12-07;
    160² before, 40 % more time): segment 3.77, 4.48, 4.98, 5.46 texels; furrows per texel
    0.0195, 0.0065, 0.0042, 0.0030 (320 to 49 furrows); width 1.44, 1.98, 2.45, 2.96; each
    step's margin as wide as at 160², where the density's last step was 0.0034 -> 0.0031."""
    n = 128
    mask = np.ones((n, n), bool)
    stats = []
    for m in (0.5, 1.0, 1.5, 2.0):
        f1, f2 = uniform_fields(n, 20, m, 0, 0.0)  # F2 = 0: one family only
        h, rec = run(mask, f1, f2, records=8192)
        r = rec[0]
        length = r["length"].sum(axis=1)
        furrowed = np.count_nonzero(h < 1 - 1e-4)
        stats.append((length.sum() / r["segments"].sum(), r["count"] / (n * n),
                      furrowed / length.sum(), 1 - h.min()))
    segment, density, width, depth = (np.array(s) for s in zip(*stats, strict=True))
    assert np.all(np.diff(segment) > 0), segment
    assert np.all(np.diff(density) < 0), density
    assert np.all(np.diff(width) > 0), width
    assert np.all(np.diff(depth) > 0), depth


def test_deterministic_for_a_seed():
    n = 64
    f1, f2 = uniform_fields(n, 30, 1.0, 120, 1.0)
    a, _ = run(np.ones((n, n), bool), f1, f2, seed=3)
    b, _ = run(np.ones((n, n), bool), f1, f2, seed=3)
    c, _ = run(np.ones((n, n), bool), f1, f2, seed=4)
    np.testing.assert_array_equal(a, b)
    assert np.mean(a != c) > 0.05


def test_jitted_program_matches_the_numpy_transcription():
    n = 64
    mask = np.ones((n, n), bool)
    mask[:, :5] = False
    mask[50:, 40:] = False
    f1, f2 = uniform_fields(n, 30, 1.0, 110, 1.3)
    centroids = np.array([[32.0, 32.0], [10.5, 50.2]], np.float32)
    key = jax.random.key(7)
    radius = wrinkles.window_radius(1.0)
    h, _ = wrinkles.height_field(jnp.asarray(mask), jnp.asarray(f1), jnp.asarray(f2),
                                 jnp.asarray(centroids), 1.0, key, radius=radius)
    h_np = numpy_furrows.height_field(mask, f1, f2, centroids, 1.0, key, radius, 1024)
    np.testing.assert_allclose(np.asarray(h), h_np, atol=1e-5)
    assert np.mean(h_np < 1) > 0.2  # there is something to compare


def test_noise_is_step_nine():
    h = jnp.full((8, 8), 0.9)
    mask = jnp.ones((8, 8), bool).at[0].set(False)
    out = np.asarray(wrinkles.add_noise(h, mask, 0.3, wrinkles.noise_field((8, 8),
                                                                           jax.random.key(0))))
    assert np.all(out[0] == 0.9) and np.all((out[1:] <= 0.9) & (out[1:] > 0.9 - 0.3))


def test_noise_values_by_hand_from_step_nine():
    """Bando 2001 §3.3 step 9, h(s,t) ← h(s,t) − r·k_noise, on a 2×3 grid with a fixed r
    written out: each value by hand (the bounds check above passes a halved amplitude)."""
    h = jnp.asarray([[1.0, 0.8, 0.5], [1.0, 0.25, 0.9]], jnp.float32)
    r = jnp.asarray([[0.5, 0.25, 1.0], [0.0, 0.75, 0.5]], jnp.float32)
    mask = jnp.asarray([[True, True, True], [True, True, False]])
    out = np.asarray(wrinkles.add_noise(h, mask, 0.4, r))
    np.testing.assert_allclose(out, [[1.0 - 0.2, 0.8 - 0.1, 0.5 - 0.4],
                                     [1.0 - 0.0, 0.25 - 0.3, 0.9]], atol=1e-7)


def test_the_noise_field_is_uniform_on_zero_one():
    """Step 9's r is "a random number between 0 and 1": 128² draws fill [0, 1) (a field
    scaled by a half, or shifted, fails): their mean 1/2 and variance 1/12 (uniform's, by
    hand) within 5 standard errors, the extremes within 1e-3 of the ends."""
    r = np.asarray(wrinkles.noise_field((128, 128), jax.random.key(3)), np.float64)
    n = r.size
    assert 0.0 <= r.min() < 1e-3 and 1.0 - 1e-3 < r.max() < 1.0
    assert abs(r.mean() - 0.5) < 5 * np.sqrt(1 / 12 / n)
    assert abs(r.var() - 1 / 12) < 5 * np.sqrt(1 / 180 / n)  # var of (r − ½)² = 1/180


# ------------------------------------------------------------------ bump normals


def test_flat_height_leaves_normals_and_a_ramp_tilts_them():
    n = np.tile([0.0, 0.0, 1.0], (4, 5, 1))
    np.testing.assert_allclose(bump.bump_normals(n, jnp.full((4, 5), 0.7), 0.5), n, atol=1e-7)
    a, k = 0.2, 0.5
    ramp = a * jnp.arange(5.0)[None, :] * jnp.ones((4, 1))  # h increases with s
    out = np.asarray(bump.bump_normals(n, ramp, k))[:, :-1]
    expected = np.array([-k * a, 0.0, 1.0]) / np.hypot(k * a, 1.0)  # eq. 4.10 by hand
    np.testing.assert_allclose(out, np.broadcast_to(expected, out.shape), atol=1e-6)


NORMALS = {
    "ordinary": [0.2, -0.3, 0.93],
    "n_z -> 0": [0.8, 0.6, 1e-7],
    "n_z = 0": [0.0, 1.0, 0.0],
}


# Jitted once for the module: check_grads' programs compile once for every point, not op
# by op.
_bump_normals = jax.jit(bump.bump_normals)


@pytest.mark.parametrize("name", NORMALS)
def test_bump_gradients(x64, name):
    rng = np.random.default_rng(0)
    n0 = np.array(NORMALS[name]) / np.linalg.norm(NORMALS[name])
    normals = np.tile(n0, (5, 6, 1)) + 1e-3 * rng.normal(size=(5, 6, 3))
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    h = rng.uniform(0.5, 1.0, (5, 6))
    for k_bump in (0.5, 40.0):  # ordinary and steep bumps
        check_grads_scaled(_bump_normals, [normals, h, k_bump], [1e-2, 1e-2, 0.1])
    grads = jax.grad(lambda k: _bump_normals(normals, h, k).sum())(0.5)
    assert np.isfinite(grads)
    out = np.asarray(bump.bump_normals(normals, h, 0.5))
    np.testing.assert_allclose(np.linalg.norm(out, axis=-1), 1.0, atol=1e-12)


def test_bump_off_the_mesh_is_zero_with_finite_gradient(x64):
    normals = jnp.zeros((3, 3, 3)).at[1, 1].set(jnp.array([0.0, 0.0, 1.0]))
    h = jnp.linspace(0, 1, 9).reshape(3, 3)
    out = _bump_normals(normals, h, 0.5)
    assert float(jnp.abs(out[0, 0]).sum()) == 0.0
    g = jax.grad(lambda k, hh: _bump_normals(normals, hh, k).sum(), argnums=(0, 1))(0.5, h)
    assert all(bool(jnp.all(jnp.isfinite(x))) for x in g)
