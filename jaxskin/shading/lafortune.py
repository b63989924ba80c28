"""The Lafortune BRDF (Bando 2001 eq. 4.15; Lafortune et al. 1997), RGB, isotropic.

    f(u, v) = ρd/π + Σᵢ max(0, Cxy,ᵢ (ux vx + uy vy) + Cz,ᵢ uz vz)^nᵢ

u (to the light) and v (to the viewer) are unit vectors in the local frame, z the normal.
The base is clamped at 0 *before* the power (pbrt-v1 does not, and gets NaN for non-integer
n); the power is exp(n log base) behind a double `where`, so values and gradients stay
finite at base = 0, at grazing angles and for exponents up to 1e4 and beyond.

Material files (what `jaxskin fit-brdf` writes):

    {"model": "lafortune", "diffuse": [r, g, b],
     "lobes": [{"Cxy": [r, g, b], "Cz": [r, g, b], "n": [r, g, b]}, ...]}

`diffuse` is ρd; the model divides it by π. `formats.read_lafortune` / `write_lafortune` read
and write them; this module converts dictionaries and computes (arrays only).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..io import InputError
from ..vectors import dot

__all__ = ["Lafortune", "brdf", "from_json", "positive_power", "shade", "skin", "to_json"]


class Lafortune(NamedTuple):
    """Lafortune lobes, RGB: `diffuse (3,)` = ρd, and `Cxy, Cz, n`, each `(lobes, 3)`."""

    diffuse: Float[Array, "3"]
    Cxy: Float[Array, "lobes 3"]
    Cz: Float[Array, "lobes 3"]
    n: Float[Array, "lobes 3"]


def brdf(p: Lafortune, u: Float[ArrayLike, "*shape 3"], v: Float[ArrayLike, "*shape 3"]):
    """f(u, v) per RGB channel, shape `(*shape, 3)`, in 1/sr (ρd divided by π).

    **Arguments:**

    - `p`: the lobes.
    - `u`, `v`: unit vectors to the light and to the viewer, local frame (z = normal).
    """
    u, v = jnp.asarray(u), jnp.asarray(v)
    return _evaluate(p, u[..., 0] * v[..., 0] + u[..., 1] * v[..., 1], u[..., 2] * v[..., 2])


def _evaluate(p: Lafortune, xy, zz):
    """f from the two products the isotropic model needs: ux vx + uy vy and uz vz."""
    base = p.Cxy * xy[..., None, None] + p.Cz * zz[..., None, None]  # (*shape, lobes, 3)
    return p.diffuse / math.pi + jnp.sum(positive_power(base, p.n), axis=-2)


def positive_power(base, n):
    """max(0, base)^n with the clamp before the power; finite values and gradients at
    base <= 0, for any n > 0 (exp(n log base) behind a double `where`)."""
    positive = base > 0
    safe = jnp.where(positive, base, 1.0)
    return jnp.where(positive, jnp.exp(n * jnp.log(safe)), 0.0)


def shade(p: Lafortune, N, L, V, ambient=0.3, light=0.7):
    """Bando 2001 eq. 4.16 on Blinn's scale: c = I_ambient ρd + π f(L, V) I_light cos θ,
    in the local frame of the (bumped) normal N. The paper writes I_light f cos θ; with
    f in 1/sr that is a factor π darker than Blinn's I_light r cos θ for the same albedo
    (f = ρd/π for a Lambertian surface), so we multiply by π: linear sRGB in the units of
    `blinn` (a white Lambertian facing the light gives I_ambient + I_light), and with the
    lobes off and ρd = r the two models agree exactly. Isotropic lobes need no tangent
    frame: uz vz = (N·L)(N·V) and ux vx + uy vy = L·V − (N·L)(N·V). The ambient
    reflectance is ρd (the paper's D).

    **Arguments:** `N (..., 3)` unit normals, `L`, `V` unit vectors to light and viewer
    (broadcastable), `ambient`, `light`: I_ambient and I_light. **Returns:** `(..., 3)`.
    """
    cos_l = dot(N, L)
    cos_v = dot(N, V)
    zz = cos_l * cos_v
    f = _evaluate(p, dot(L, V) - zz, zz)
    return ambient * p.diffuse + (math.pi * light) * f * jnp.maximum(cos_l, 0.0)[..., None]


def skin(dtype=jnp.float32) -> Lafortune:
    """The 3-lobe fit to measured skin (pbrt-v1 `materials/skin.cpp`; constants.md)."""
    a = lambda x: jnp.asarray(x, dtype)  # noqa: E731
    return Lafortune(
        diffuse=a([0.428425, 0.301341, 0.331054]),
        Cxy=a([[-1.131747, -1.016939, -0.966018], [-0.546570, -0.643533, -0.638934],
               [-0.998888, -1.020153, -1.027479]]),
        Cz=a([[-1.209182, -1.462488, -1.222419], [0.380123, 0.410559, 0.437367],
              [0.857998, 0.703913, 0.573625]]),
        n=a([[6.421658, 3.699932, 3.524889], [3.685044, 4.266495, 4.539742],
             [64.208486, 63.919687, 43.809866]]),
    )


def to_json(p: Lafortune, **extra) -> dict:
    """The material-file dictionary of `p` (plus any `extra` keys, e.g. fit statistics)."""
    f = lambda x: [float(c) for c in np.asarray(x)]  # noqa: E731
    lobes = [{"Cxy": f(p.Cxy[i]), "Cz": f(p.Cz[i]), "n": f(p.n[i])} for i in range(len(p.n))]
    return {"model": "lafortune", "diffuse": f(p.diffuse), "lobes": lobes, **extra}


def from_json(doc, source="<json>", dtype=jnp.float32) -> Lafortune:
    """Check and read a material dictionary; `InputError` names the key that is wrong."""

    def rgb(value, key):
        ok = isinstance(value, list) and len(value) == 3 and all(
            isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c)
            for c in value)
        if not ok:
            raise InputError(f"expected three finite numbers [r, g, b], got {value!r}",
                             source, key=key)
        return value

    if not isinstance(doc, dict) or doc.get("model") != "lafortune":
        raise InputError("expected a JSON object with \"model\": \"lafortune\"", source,
                         key="model")
    diffuse = rgb(doc.get("diffuse"), "diffuse")
    if min(diffuse) < 0:
        raise InputError(f"diffuse ρd must be >= 0, got {diffuse}", source, key="diffuse")
    lobes = doc.get("lobes")
    if not isinstance(lobes, list) or not lobes:
        raise InputError("expected a non-empty list of lobes", source, key="lobes")
    Cxy, Cz, n = [], [], []
    for i, lobe in enumerate(lobes):
        if not isinstance(lobe, dict) or set(lobe) - {"Cxy", "Cz", "n"}:
            raise InputError("expected an object with keys Cxy, Cz, n", source,
                             key=f"lobes[{i}]")
        Cxy.append(rgb(lobe.get("Cxy"), f"lobes[{i}].Cxy"))
        Cz.append(rgb(lobe.get("Cz"), f"lobes[{i}].Cz"))
        n.append(rgb(lobe.get("n"), f"lobes[{i}].n"))
        if min(n[-1]) <= 0:
            raise InputError(f"exponents must be > 0, got {n[-1]}", source,
                             key=f"lobes[{i}].n")
    a = lambda x: jnp.asarray(x, dtype)  # noqa: E731
    return Lafortune(a(diffuse), a(Cxy), a(Cz), a(n))
