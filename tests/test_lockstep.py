"""The parallel (lockstep) furrow program: the sequential program's character — coverage,
orientation histograms, T-junctions, furrow lengths — on the hand and the cylindrical arm;
the measures themselves against references computed another way; the scene key."""

import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxskin import furrow_stats, lockstep, texture, wrinkles
from jaxskin.io import InputError
from jaxskin.scene import furrow_method, load_scene

RECORDS = 4096


def both_programs(name, size):
    """(mask, (h, record) sequential, (h, record) parallel) for a built-in scene."""
    sc = load_scene(name, [f"texture.size={size}"])
    s = texture.setup(sc.config.texture)
    k, key = sc.config.texture.k_scale, jax.random.key(sc.config.texture.seed)
    hs, rs = wrinkles.height_field(s.mask, s.field1, s.field2,
                                   jnp.asarray(s.tmap.centroids(), jnp.float32), k, key,
                                   radius=wrinkles.window_radius(k), records=RECORDS,
                                   wrap=s.tmap.wrap_x)
    hp, rp = lockstep.height_field(s.mask, s.field1, s.field2, k, key, records=RECORDS,
                                   wrap=s.tmap.wrap_x)
    assert max(int(rs.count.max()), int(rp.count.max())) <= RECORDS  # every furrow recorded
    return (np.asarray(s.mask), (np.asarray(hs), wrinkles.to_numpy_record(rs, RECORDS)),
            (np.asarray(hp), wrinkles.to_numpy_record(rp, RECORDS)))


@pytest.fixture(scope="module", params=["hand", "arm"])
def pair(request):
    return request.param, both_programs(request.param, 256)


@pytest.mark.slow  # both programs compiled for two scenes: 20–70 s
def test_coverage_and_orientations_within_ten_percent(pair):
    """Measured at 256²: coverage 0.764 / 0.764 (hand), 0.833 / 0.799 (arm); orientation
    histogram distances 0.053–0.066 (of 1). The issue's bound: 10 %."""
    name, (mask, (hs, rs), (hp, rp)) = pair
    cs, cp = furrow_stats.coverage(hs, mask), furrow_stats.coverage(hp, mask)
    assert abs(cp - cs) / cs < 0.10, (name, cs, cp)
    for p in range(2):
        d = furrow_stats.histogram_distance(furrow_stats.orientation_histogram(rs[p]["owner"], mask),
                                            furrow_stats.orientation_histogram(rp[p]["owner"], mask))
        assert d < 0.10, (name, p, d)


@pytest.mark.slow  # both programs compiled for two scenes: 20–70 s
def test_t_junctions(pair):
    """Furrows end on furrows: measured shares of halves ending so 0.53–0.80 (parallel),
    within 0.14 of the sequential program's. And an end that says so does touch another
    furrow of its pass (the owner image within a texel)."""
    name, (mask, (hs, rs), (hp, rp)) = pair
    for p in range(2):
        r = rp[p]
        share = [furrow_stats.t_junctions(x[p]) / x[p]["reason"].size for x in (rs, rp)]
        assert share[1] > 0.4 and abs(share[1] - share[0]) < 0.2, (name, p, share)
        touching = 0
        ends = np.argwhere(r["reason"] == wrinkles.END_FURROW)
        for fid, half in ends:
            ix, iy = (int(np.floor(c)) for c in r["end"][fid, half])
            around = r["owner"][max(iy - 1, 0):iy + 2, max(ix - 1, 0):ix + 2]
            touching += np.any((around >= 0) & (around != fid))
        assert touching / len(ends) > 0.95, (name, p, touching, len(ends))


@pytest.mark.slow  # both programs compiled for two scenes: 20–70 s
def test_furrow_length_distribution(pair):
    """Measured at 256²: KS distance 0.075–0.174; medians and 90th percentiles within 27 %."""
    name, (mask, (hs, rs), (hp, rp)) = pair
    for p in range(2):
        ls, lp = furrow_stats.furrow_lengths(rs[p]), furrow_stats.furrow_lengths(rp[p])
        assert furrow_stats.ks_distance(ls, lp) < 0.25, (name, p)
        for q in (50, 90):
            a, b = np.percentile(ls, q), np.percentile(lp, q)
            assert abs(b - a) / a < 0.35, (name, p, q, a, b)


def test_deterministic_for_a_seed_and_one_per_texel_owner():
    n = 96
    f1 = np.broadcast_to(np.array([1.0, -0.3], np.float32), (n, n, 2))
    f2 = np.broadcast_to(np.array([0.2, 0.9], np.float32), (n, n, 2))
    mask = np.ones((n, n), bool)
    mask[:, :10] = False

    def run(seed):
        return lockstep.height_field(mask, f1, f2, 1.0, jax.random.key(seed), records=2048)

    (a, ra), (c, _) = run(3), run(4)
    with jax.enable_x64(True):  # a caller's float64 changes nothing (and does not break it)
        b, _ = run(3)
    np.testing.assert_array_equal(a, b)
    assert b.dtype == jnp.float32
    assert np.mean(a != c) > 0.05
    assert np.all(np.asarray(a)[~mask] == 1.0) and np.mean(np.asarray(a)[mask] < 1) > 0.5
    # The owner image holds the ids given, 0 … count − 1.
    for p in range(2):
        own = np.asarray(ra.owner[p])
        assert own.max() == int(ra.count[p]) - 1


# ------------------------------------------------------------------ the measures


def test_coverage_measure():
    h = np.ones((4, 5))
    h[1, 1:4] = 0.7
    h[3, 0] = 1 - 1e-6  # within eps of 1: not a furrow
    mask = np.ones((4, 5), bool)
    mask[0] = False
    assert furrow_stats.coverage(h, mask) == pytest.approx(3 / 15)


@pytest.mark.parametrize("angle", [0.0, 30.0, 75.0, 120.0])
def test_orientation_histogram_peaks_at_drawn_lines(angle):
    """Parallel lines drawn at a known angle (screen frame, y up): the histogram's peak bin
    holds the angle, and the histogram sums to 1."""
    n = 96
    y, x = np.mgrid[0:n, 0:n]
    a = np.radians(angle)
    across = -(x + 0.5) * np.sin(a) + (n - y - 0.5) * np.cos(a)  # distance along the normal
    owner = np.where(np.mod(across, 8.0) < 1.0, 0, -1)
    hist = furrow_stats.orientation_histogram(owner, np.ones((n, n), bool))
    assert hist.sum() == pytest.approx(1.0)
    peak = 10.0 * np.argmax(hist)
    assert peak <= angle % 180 < peak + 10.0 or abs(peak + 5 - angle) <= 6, (angle, peak)
    assert hist.max() > 0.5


def test_histogram_and_ks_distances_by_hand():
    assert furrow_stats.histogram_distance([0.5, 0.5, 0.0], [0.0, 0.5, 0.5]) == pytest.approx(0.5)
    assert furrow_stats.histogram_distance([1, 0], [0, 1]) == pytest.approx(1.0)
    # ECDFs of {1, 2, 3, 4} and {3, 4, 5, 6}: the gap is largest from 2 to 3 (2/4).
    assert furrow_stats.ks_distance([1, 2, 3, 4], [3, 4, 5, 6]) == pytest.approx(0.5)
    assert furrow_stats.ks_distance([1, 2], [1, 2]) == 0.0
    assert furrow_stats.ks_distance([1, 2], [3, 4]) == 1.0


def test_t_junctions_and_lengths_from_a_record():
    rec = {"reason": np.array([[wrinkles.END_FURROW, wrinkles.END_BORDER],
                               [wrinkles.END_LIMIT, wrinkles.END_FURROW],
                               [wrinkles.END_FURROW, wrinkles.END_ZERO]]),
           "length": np.array([[3.0, 4.0], [10.0, 0.5], [0.0, 0.0]])}
    assert furrow_stats.t_junctions(rec) == 3
    np.testing.assert_allclose(furrow_stats.furrow_lengths(rec), [7.0, 10.5, 0.0])


# ------------------------------------------------------------------ the scene key


def test_scene_key_picks_the_program(monkeypatch):
    calls = []
    real = lockstep.height_field
    monkeypatch.setattr(lockstep, "height_field", lambda *a, **k: calls.append(1) or real(*a, **k))
    texture.furrows.cache_clear()
    try:
        sc = load_scene("hand", ["texture.size=32", "wrinkles.method=parallel"])
        assert sc.config.texture.method == "parallel"
        h, _ = texture.furrows(sc.config.texture)
        assert calls == [1] and h.shape == (32, 32)
        seq = load_scene("hand", ["texture.size=32", "wrinkles.method=sequential"])
        assert seq.config.texture.method == "sequential" and seq.config != sc.config
        texture.furrows(seq.config.texture)
        assert calls == [1]
    finally:
        texture.furrows.cache_clear()


def test_auto_is_the_faster_program_on_this_device():
    """On a CPU the sequential program below 2048² (quicker from a cold start: it compiles
    about 1 s sooner), the parallel one from 2048² (as quick cold there, quicker above, and
    3x quicker warm); on a GPU or TPU always the parallel one."""
    cpu = jax.default_backend() == "cpu"
    for size, on_cpu in ((32, "sequential"), (512, "sequential"), (1024, "sequential"),
                         (2047, "sequential"), (2048, "parallel"), (4096, "parallel")):
        assert furrow_method("auto", size) == (on_cpu if cpu else "parallel"), size
        assert furrow_method("parallel", size) == "parallel"
        assert furrow_method("sequential", size) == "sequential"
    assert load_scene("hand", ["texture.size=32"]).config.texture.method == (
        "sequential" if cpu else "parallel")
    assert load_scene("hand", ["texture.size=2048"]).config.texture.method == "parallel"
    assert load_scene("hand", ["texture.size=2048", "wrinkles.method=sequential"]
                      ).config.texture.method == "sequential"


def test_bad_method_is_a_one_line_error(tmp_path):
    with pytest.raises(InputError, match="wrinkles.method.*auto, parallel, sequential"):
        load_scene("hand", ["wrinkles.method=fast"])
    proc = subprocess.run([sys.executable, "-m", "jaxskin", "render", "hand",
                           "-D", "wrinkles.method=fast", "-o", str(tmp_path / "out")],
                          capture_output=True, text=True)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.startswith("jaxskin: error:") and "wrinkles.method" in proc.stderr
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


@pytest.mark.slow  # compiles the render's texture maps in float64: 10–30 s
def test_parallel_scene_differentiable_in_k_noise_and_k_bump(x64):
    """The height field is a constant of the render (as the sequential one is); the
    parameters after it are gradient-checked, float64, on the parallel program's field."""
    from conftest import check_grads_scaled

    sc = load_scene("hand", ["texture.size=24", "wrinkles.method=parallel"])
    params = {k: jnp.asarray(v, jnp.float64) for k, v in sc.params.items()}

    def f(k_noise, k_bump):
        p = {**params, "wrinkles.k_noise": k_noise, "wrinkles.k_bump": k_bump}
        return texture.texture_maps(sc.config, p)["normals"]

    check_grads_scaled(f, [0.2, 0.5], [0.05, 0.05], order=1)
    h0, _ = texture.furrows(sc.config.texture)
    assert h0.dtype == jnp.float32 and np.mean(np.asarray(h0) < 1) > 0.2


@pytest.mark.parametrize("count", [1, 7, 1849, 466489, 2**24])
def test_seed_order_is_a_permutation(count):
    """The rounds' scrambled order visits every cell once, up to an 8192² texture's 2²⁴
    cells of 2 texels (where j·p would overflow 32 bits if multiplied at once)."""
    order = np.asarray(lockstep._scramble(jnp.arange(count, dtype=jnp.int32), count))
    np.testing.assert_array_equal(np.sort(order), np.arange(count))
    if count > 7:
        assert np.mean(np.abs(np.diff(order)) > 1) > 0.9  # neighbours in the queue are apart
