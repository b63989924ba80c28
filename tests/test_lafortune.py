"""The Lafortune BRDF: reciprocity, the clamp, gradients at grazing angles and huge exponents."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import check_grads_scaled

from jaxskin.formats import read_lafortune, write_lafortune
from jaxskin.io import InputError
from jaxskin.shading import lafortune as L


def direction(theta_deg, phi_deg):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


def test_the_published_values_at_the_normal(x64):
    """By hand, lobes written out from constants.md: normal incidence and exitance.
    (Off-normal: test_references.py. Reciprocity is not tested: every term is a product
    ux vx, uy vy, uz vz, symmetric by construction.)"""
    p = L.skin(jnp.float64)
    u = v = np.array([0.0, 0.0, 1.0])
    diffuse = np.array([0.428425, 0.301341, 0.331054]) / np.pi
    lobe1 = np.array([0.380123, 0.410559, 0.437367]) ** np.array([3.685044, 4.266495, 4.539742])
    lobe2 = np.array([0.857998, 0.703913, 0.573625]) ** np.array([64.208486, 63.919687, 43.809866])
    np.testing.assert_allclose(L.brdf(p, u, v), diffuse + lobe1 + lobe2,
                               rtol=2e-15)  # measured 2.2e-16


def test_negative_base_is_clamped_to_zero_not_nan(x64):
    p = L.Lafortune(jnp.zeros(3), jnp.full((1, 3), 1.0), jnp.full((1, 3), 1.0), jnp.full((1, 3), 2.5))
    u, v = direction(60, 0), direction(60, 180)  # ux vx < 0 and larger than uz vz
    f = L.brdf(p, u, v)
    np.testing.assert_array_equal(f, 0.0)
    grads = jax.grad(lambda q: L.brdf(q, u, v).sum())(p)
    assert all(bool(jnp.all(jnp.isfinite(g))) for g in grads)


POINTS = [
    ("ordinary", direction(30, 10), direction(40, 200), 1.0),
    ("grazing light", direction(89.9999, 0), direction(30, 180), 1.0),
    ("grazing both", direction(89.9999, 0), direction(89.9999, 180), 1.0),
    ("huge exponent", direction(1, 0), direction(1, 180), 1e4),
]


@jax.jit  # once for the module: the points share check_grads' programs, not op by op
def _brdf(diffuse, Cxy, Cz, n, u, v):
    return L.brdf(L.Lafortune(diffuse, Cxy, Cz, n), u, v)


@pytest.mark.parametrize("name, u, v, n_scale", POINTS, ids=[p[0] for p in POINTS])
def test_gradients_wrt_lobes_and_directions(x64, name, u, v, n_scale):
    p = L.skin(jnp.float64)
    n = p.n * n_scale

    f = _brdf
    args = [p.diffuse, p.Cxy, p.Cz, n, u, v]
    scales = [0.1, 0.1, 0.1, n / 100, 1e-3, 1e-3]
    check_grads_scaled(f, args, scales, eps=1e-4)
    grads = jax.jacrev(f, argnums=range(6))(*[jnp.asarray(a) for a in args])
    assert all(bool(jnp.all(jnp.isfinite(g))) for g in grads)
    assert bool(jnp.all(jnp.isfinite(f(*args)))) and bool(jnp.all(f(*args) >= 0))


def test_no_nan_or_infinity_is_ever_written_or_read(tmp_path):
    p = L.skin()._replace(diffuse=jnp.asarray([0.1, float("nan"), 0.2]))
    with pytest.raises(ValueError, match="not JSON compliant"):
        write_lafortune(p, tmp_path / "nan.json")
    assert not list(tmp_path.iterdir())  # nothing left behind, not even a temporary
    (tmp_path / "inf.json").write_text('{"model": "lafortune", "diffuse": [Infinity, 0, 0]}')
    with pytest.raises(InputError, match="Infinity is not a JSON number"):
        read_lafortune(tmp_path / "inf.json")


def test_json_round_trip(tmp_path):
    p = L.skin()
    write_lafortune(p, tmp_path / "skin.json", fit={"note": "x"})
    q = read_lafortune(tmp_path / "skin.json")
    for a, b in zip(p, q, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-7)
    assert json.loads((tmp_path / "skin.json").read_text())["fit"] == {"note": "x"}


BAD = [
    ({"model": "phong"}, "model"),
    ({"model": "lafortune", "diffuse": [0.1, 0.2], "lobes": []}, "diffuse"),
    ({"model": "lafortune", "diffuse": [0.1, 0.2, -0.3], "lobes": []}, "diffuse"),
    ({"model": "lafortune", "diffuse": [0.1, 0.2, 0.3], "lobes": []}, "lobes"),
    ({"model": "lafortune", "diffuse": [0.1, 0.2, 0.3],
      "lobes": [{"Cxy": [1, 1, 1], "Cz": [1, 1, 1], "n": [1, 0, 1]}]}, "lobes[0].n"),
    ({"model": "lafortune", "diffuse": [0.1, 0.2, 0.3],
      "lobes": [{"Cxy": [1, 1, 1], "Cz": [1, "a", 1], "n": [1, 1, 1]}]}, "lobes[0].Cz"),
    ({"model": "lafortune", "diffuse": [0.1, 0.2, 0.3],
      "lobes": [{"Cxy": [1, 1, 1], "Cz": [1, 1, 1], "n": [1, 1, 1], "m": 2}]}, "lobes[0]"),
]


@pytest.mark.parametrize("doc, key", BAD)
def test_bad_material_names_the_key(tmp_path, doc, key):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError) as info:
        read_lafortune(path)
    assert str(info.value).startswith(f"{path}: key '{key}'")
