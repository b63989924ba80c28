"""The benchmark scripts are not run by the suite (they take minutes); their entry points
are, on tiny inputs, so that an API change cannot break them unnoticed."""

import sys
from pathlib import Path

import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
import bench_brdf  # noqa: E402
import bench_km  # noqa: E402
import bench_render  # noqa: E402
import bench_wrinkles  # noqa: E402


def test_bench_km_pipelines_agree_on_a_tiny_texture():
    grid_wl = np.arange(380.0, 781.0, 40.0)
    S, K = bench_km.load_materials(grid_wl)
    X = bench_km.thickness_maps(8)
    Rg = bench_km.skin_reflectance(grid_wl)
    args = [jnp.asarray(a, jnp.float32) for a in (S, K, X, Rg)]
    np.testing.assert_allclose(bench_km.over_skin(*args), bench_km.naive_over_skin(*args),
                               atol=1e-5)


def test_bench_wrinkles_and_render_inputs():
    sc, s, cent, radius = bench_wrinkles.inputs(32)
    assert s.mask.shape == (32, 32) and radius > 0 and cent.shape[1] == 2
    assert bench_render.OVERRIDES and callable(bench_render.main)


def test_bench_brdf_baseline_model_matches_ours():
    from jaxskin.shading import lafortune

    rng = np.random.default_rng(0)
    theta = np.concatenate([[np.log(0.4)], [-1.0, -0.5, -1.0], [0.8, 0.4, -1.2],
                            np.log([60.0, 4.0, 6.0])])
    wi = np.abs(rng.normal(size=(5, 3)))
    wo = np.abs(rng.normal(size=(5, 3)))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    from jaxskin.fitting.brdf import _unpack

    ours = np.asarray(lafortune.brdf(_unpack(jnp.asarray(theta), 3), wi, wo))[:, 0]
    np.testing.assert_allclose(bench_brdf.numpy_model(theta, wi, wo), ours, rtol=1e-5)


def test_the_runner_knows_every_benchmark_and_rejects_others(capsys):
    import run

    for module in run.BENCHMARKS.values():
        assert (Path(run.__file__).parent / f"{module}.py").is_file()
    assert run.main(["nope"]) == 2 and "unknown benchmark" in capsys.readouterr().err


def test_bench_makeup_colour_difference():
    import bench_makeup

    a = np.random.default_rng(0).uniform(0, 1, (4, 5, 3))
    mask = np.ones((4, 5), bool)
    assert np.all(bench_makeup.delta_e(a, a, mask) == 0)
    b = a.copy()
    b[0, 0] = [1.0, 0.0, 0.0] if a[0, 0, 1] > 0.5 else [0.0, 1.0, 0.0]
    assert bench_makeup.delta_e(a, b, mask).max() > 10 and callable(bench_makeup.main)


def test_bench_km_calibration_scaling_inputs_and_table():
    m = bench_km.synthetic_measurement(21)
    assert m.R.shape == (2, 21) and m.wavelength_nm[0] == 380 and m.wavelength_nm[-1] == 780
    text = bench_km.scaling_section([(21, 0.0, 0.01, 0.5, 3, True), (21, 20.0, 0.01, None, 4,
                                                                      True)],
                                    {0.0: (400.0, 420.0, 5.0, (3.0, 500.0))}, 1.0)
    assert "| 21 | 0 | 0.010 | 0.500 | 50.0 | 3 | True |" in text


def test_gradient_benchmark_measures_every_model_and_the_maps(capsys):
    import bench_gradients
    import run

    cases = bench_gradients.cases(quick=True)
    labels = " ".join(c[0] for c in cases)
    assert all(m in labels for m in ("Blinn", "Lafortune", "spectral"))
    assert "per-texel thickness maps" in [c[1] for c in cases]
    assert "gradients" in run.BENCHMARKS
    assert run.main(["--device", "nope"]) == 2 and "unknown benchmark" in capsys.readouterr().err


def test_gpu_check_script_parses_and_rejects_unknown_arguments():
    import subprocess

    script = Path(__file__).resolve().parent.parent / "benchmarks" / "gpu_check.sh"
    assert subprocess.run(["bash", "-n", str(script)]).returncode == 0
    r = subprocess.run(["bash", str(script), "--nope"], capture_output=True, text=True)
    assert r.returncode == 2 and "unknown argument --nope" in r.stderr


def test_benchmark_help_writes_nothing_and_typos_are_refused(tmp_path, capsys):
    """`bench_wrinkles.py --help` must not run the whole benchmark and rewrite RESULTS.md:
    every option is parsed first; a misspelt one is an error, not a full-size run."""
    import bench_forms
    import common
    import pytest

    results = Path(common.RESULTS)
    before = results.read_bytes()
    for main, argv in ((bench_wrinkles.main, ["--help"]), (bench_forms.main, ["--help"]),
                       (bench_wrinkles.main, ["--quik"]), (bench_forms.main, ["plain", "--quik"]),
                       (bench_forms.main, [])):
        with pytest.raises(SystemExit) as e:
            main(argv)
        assert e.value.code == (0 if argv == ["--help"] else 2), argv
    assert results.read_bytes() == before
    assert "--speed" in capsys.readouterr().out
    assert common.command("benchmarks/limits.py", ["--quick", "--results", "/x/R.md",
                                                   "--repeat", "3"]) == \
        "python benchmarks/limits.py --quick --repeat 3"
