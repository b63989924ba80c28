"""A linear map with a transpose written by hand: fast reverse mode that keeps forward mode.

`linear_call(fun, transpose, residuals, linear)` evaluates `fun(*residuals, *linear)`, a
function linear in the `linear` arguments. Forward mode (`jax.jvp`, `jax.jacfwd`, optimistix's
Levenberg–Marquardt) evaluates `fun` on the tangents; reverse mode (`jax.grad`, `jax.vjp`)
calls `transpose(*residuals, ct)`, which returns the cotangents of the `linear` arguments:
the hand-written transpose replaces the one JAX would derive from `fun`'s program. Use it
for the tangent inside a `jax.custom_jvp` rule: the primal and forward mode stay what they
were, and reverse mode gets the hand-written rule.

Unlike `jax.custom_derivatives.linear_call`, linear arguments that are known (a zero tangent
that a `custom_jvp` rule instantiated) are accepted, and `vmap` works: batched, the map is
`vmap(fun)` and its transpose JAX's own (correct, not fast; `jax.jacfwd` is unaffected, it
only evaluates `fun`). Second derivatives differentiate `fun` by autodiff.
"""

from __future__ import annotations

import jax
import jax.extend
from jax.interpreters import ad, batching, mlir

__all__ = ["linear_call"]


def linear_call(fun, transpose, residuals: tuple, linear: tuple):
    """`fun(*residuals, *linear)` (one array), with reverse mode by `transpose`.

    **Arguments:**

    - `fun`: a function of the residuals (any inputs) and the linear inputs, returning one
      array, linear in the linear inputs.
    - `transpose`: `transpose(*residuals, ct)` → a tuple of arrays shaped like `linear`,
      the transpose of `fun` with respect to the linear inputs at cotangent `ct`.
    - `residuals`, `linear`: tuples of arrays.

    `fun` and `transpose` are compared by identity in traces: pass module-level functions
    (or one `functools.partial` per call site), not lambdas made afresh on every call.
    """
    return _linear_p.bind(*residuals, *linear, fun=fun, transpose=transpose,
                          n_res=len(residuals))


def _impl(*args, fun, transpose, n_res):
    return fun(*args)


def _abstract(*args, fun, transpose, n_res):
    out = jax.eval_shape(fun, *(jax.ShapeDtypeStruct(a.shape, a.dtype) for a in args))
    return jax.core.ShapedArray(out.shape, out.dtype)


def _transpose(ct, *args, fun, transpose, n_res):
    residuals, linear = args[:n_res], args[n_res:]
    if any(ad.is_undefined_primal(r) for r in residuals):
        raise ValueError("linear_call: only the linear arguments can be transposed")
    undefined = [ad.is_undefined_primal(x) for x in linear]
    if type(ct) is ad.Zero:
        return [None] * n_res + [ad.Zero(x.aval) if u else None
                                 for x, u in zip(linear, undefined, strict=True)]
    cts = transpose(*residuals, ct)
    return [None] * n_res + [c if u else None for c, u in zip(cts, undefined, strict=True)]


def _jvp(primals, tangents, *, fun, transpose, n_res):
    tangents = [ad.instantiate_zeros(t) for t in tangents]
    return jax.jvp(fun, primals, tangents)


def _batch(args, dims, *, fun, transpose, n_res):
    return jax.vmap(fun, in_axes=dims)(*args), 0


_linear_p = jax.extend.core.Primitive("jaxskin_linear_call")
_linear_p.def_impl(_impl)
_linear_p.def_abstract_eval(_abstract)
mlir.register_lowering(_linear_p, mlir.lower_fun(_impl, multiple_results=False))
ad.primitive_transposes[_linear_p] = _transpose
ad.primitive_jvps[_linear_p] = _jvp
batching.primitive_batchers[_linear_p] = _batch
