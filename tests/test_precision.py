"""Every float32 product at full precision (`jaxskin.precision`): no matmul, einsum or
convolution left at XLA's default, which a GPU may compute in TF32 (issue 19).

The renders (Blinn, Lafortune, perspective, the cosmetics model with either SSS method) and
the KM fit's solver are traced and their jaxprs walked, sub-programs included (scan, cond,
custom JVP, checkpoint, pjit). A product added with plain `@` fails here.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.extend.core import ClosedJaxpr, Jaxpr

from jaxskin import render
from jaxskin.scene import load_scene

PRODUCTS = ("dot_general", "conv_general_dilated")
HIGHEST = jax.lax.Precision.HIGHEST


def _sub_jaxprs(value):
    if isinstance(value, ClosedJaxpr):
        yield value.jaxpr
    elif isinstance(value, Jaxpr):
        yield value
    elif isinstance(value, tuple | list):
        for v in value:
            yield from _sub_jaxprs(v)


def products(jaxpr):
    """`(primitive name, precision, operand dtypes)` of every product in `jaxpr`, nested
    programs included."""
    for eqn in jaxpr.eqns:
        if eqn.primitive.name in PRODUCTS:
            yield (eqn.primitive.name, eqn.params.get("precision"),
                   tuple(str(v.aval.dtype) for v in eqn.invars))
        for value in eqn.params.values():
            for sub in _sub_jaxprs(value):
                yield from products(sub)


def _is_highest(precision):
    if precision is None:
        return False
    pair = precision if isinstance(precision, tuple) else (precision, precision)
    return all(p == HIGHEST for p in pair)


def _render_products(name, overrides):
    sc = load_scene(name, overrides)
    arrays = render.prepare(sc.config).arrays
    loss = lambda p, a: jnp.sum(render.render_prepared(sc.config, p, a))  # noqa: E731
    # Forward and reverse: the transposed products must keep the precision too.
    jaxpr = jax.make_jaxpr(jax.value_and_grad(loss))(sc.params, arrays).jaxpr
    return list(products(jaxpr))


@pytest.mark.parametrize("name, overrides", [
    ("hand", ["wrinkles.enabled=false"]),
    ("hand", ["material.model=lafortune", "wrinkles.enabled=false"]),
    ("hand", ["camera.projection=perspective", "wrinkles.enabled=false"]),
    ("makeup", ["wrinkles.enabled=false", "light.shadows=false"]),
    ("makeup", ["wrinkles.enabled=false", "light.shadows=false", "sss.method=separable"]),
], ids=["blinn", "lafortune", "perspective", "makeup-fft", "makeup-separable"])
def test_every_product_of_a_render_and_its_gradient_is_at_highest(name, overrides):
    small = ["texture.size=32", "camera.size=16"]
    found = _render_products(name, small + overrides)
    assert found, "no product traced: the walk missed the programs"
    loose = [f for f in found if not _is_highest(f[1])]
    assert not loose, loose


def test_the_km_fit_solver_uses_highest_and_float64():
    from jaxskin.fitting import km as fit_km

    n = 5
    with jax.enable_x64(True):
        f64 = lambda a: jnp.asarray(a, jnp.float64)  # noqa: E731
        args = (f64([0.05, 0.15]), f64(np.full((n, 2), 0.3)), f64(np.full(n, 0.5)),
                f64(np.full(n, 0.04)), f64(0.1), jnp.ones(n, bool), f64(np.zeros(n)),
                (f64(0.04), f64(0.6)))  # with Saunderson's correction: its products too
        y0 = f64(np.zeros((n, 2)))
        found = []
        for solve in (fit_km._solve_coupled, fit_km._solve_separable):
            found += list(products(jax.make_jaxpr(solve)(y0, args).jaxpr))
    assert found
    assert all(_is_highest(p) for _, p, _ in found), found
    assert all(d == "float64" for _, _, dtypes in found for d in dtypes), found


def test_the_walk_finds_a_product_at_the_default():
    """The check itself can fail: a plain `@` is seen, at default precision."""
    jaxpr = jax.make_jaxpr(lambda a: jax.lax.map(lambda r: r @ a, a))(jnp.ones((3, 3)))
    found = list(products(jaxpr.jaxpr))
    assert len(found) == 1 and not _is_highest(found[0][1])
