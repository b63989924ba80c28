"""Mixtures of pigments in a base by the two-constant Kubelka–Munk rule.

The scattering and absorption of a mixture are the concentration-weighted sums of its
components' (Duncan 1940; the basis of computer colour matching, Allen 1966):

    S_mix(λ) = Σ_i c_i S_i(λ),    K_mix(λ) = Σ_i c_i K_i(λ).

Here S_i, K_i are each component's own coefficients per mm (what `jaxskin calibrate`
fits to a layer of the pure component), so the c_i are **volume fractions**: a
coefficient per unit length is a sum over the particles in a unit volume, and a component
at volume fraction c_i brings c_i of its pure particles' share. Fractions by weight w_i
become volume fractions with the densities ρ_i: c_i = (w_i/ρ_i) / Σ_j (w_j/ρ_j).

Pure functions of arrays, differentiable in every argument (linear in S, K and c; the
reflectances are `km`'s), no files.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from . import km

__all__ = ["mix", "reflectance", "volume_fractions", "weight_fractions"]


def mix(
    S: Float[ArrayLike, " m *bands"],
    K: Float[ArrayLike, " m *bands"],
    c: Float[ArrayLike, " m"],
) -> tuple[Float[Array, "*bands"], Float[Array, "*bands"]]:
    """S and K of a mixture: the two-constant rule Σ c_i S_i, Σ c_i K_i.

    **Arguments:**

    - `S`, `K`: the components' scattering and absorption per mm, components first
      (`(m, n)` for m components on n bands).
    - `c`: the components' volume fractions `(m,)`, >= 0 (a zero drops the component;
      the rule itself does not need them to sum to 1, the commands do).

    **Returns:** `(S_mix, K_mix)`, each of shape `S.shape[1:]`, per mm.
    """
    S, K, c = (jnp.asarray(a) for a in (S, K, c))
    if S.shape != K.shape or S.ndim < 1 or c.shape != S.shape[:1]:
        raise ValueError(f"mixture.mix: S {S.shape} and K {K.shape} need one row per "
                         f"component, and c {c.shape} one value per row")
    c = c.reshape(c.shape + (1,) * (S.ndim - 1))
    return jnp.sum(c * S, axis=0), jnp.sum(c * K, axis=0)


def reflectance(S, K, c, thickness_mm=None, background=None):
    """Reflectance of the mixture `mix(S, K, c)`: opaque (`km.r_inf`) when `thickness_mm`
    is None, else a film of that thickness over an opaque `background` of reflectance
    `(n,)` or a number (`km.layer` and `km.over`).

    **Returns:** `R (n,)`.
    """
    S_mix, K_mix = mix(S, K, c)
    if thickness_mm is None:
        return km.r_inf(S_mix, K_mix)
    if background is None:
        raise ValueError("mixture.reflectance: a film (thickness_mm) needs a background")
    R, T = km.layer(S_mix, K_mix, thickness_mm)
    return km.over(R, T, background)


def volume_fractions(w, density):
    """Weight fractions `w (m,)` → volume fractions, with the components' densities
    `density (m,)` (any one unit): c_i = (w_i/ρ_i) / Σ_j (w_j/ρ_j)."""
    v = jnp.asarray(w) / jnp.asarray(density)
    return v / jnp.sum(v)


def weight_fractions(c, density):
    """The inverse of `volume_fractions`: w_i = c_i ρ_i / Σ_j c_j ρ_j."""
    m = jnp.asarray(c) * jnp.asarray(density)
    return m / jnp.sum(m)
