"""Every differentiable stage on stiff and extreme inputs, float32 and float64: no
non-finite value or gradient anywhere; float32 within 1e-5 of float64 (the outputs are
reflectances, colours and unit vectors). The same sweep writes RESULTS.md's table; the
benchmark adds a 4096² bump map and a 2048² blur, which need about 10 GB."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
import stability  # noqa: E402

CASES = stability.cases()


@pytest.mark.parametrize("stage, fn, inputs", CASES, ids=[c[0] for c in CASES])
def test_no_non_finite_values_or_gradients(stage, fn, inputs):
    row = stability.run(stage, fn, inputs)
    for key in ("nonfinite_f32", "nonfinite_f64", "nonfinite_grad_f32", "nonfinite_grad_f64"):
        assert row[key] == 0, (key, row)
    assert row["max_f32_error"] < 1e-5, row
