"""Kelemen / Szirmay-Kalos specular for skin and cosmetic layers (Huang et al. 2013 eq. 5;
d'Eon & Luebke, GPU Gems 3 ch. 14; constants.md).

    f_spec(L, V) = P_H(H) F(H·L) / (2 (1 + L·V)),   2 (1 + L·V) = |L + V|²
    P_H = exp(−tan²α / m²) / (m² cos⁴α),  cos α = N·H   (Beckmann, no π)
    F = F0 + (1 − F0)(1 − H·L)^5  (Schlick, F0 = 0.028 for skin)

`specular` returns the reflected radiance factor ρ_s (N·L) f_spec, as GPU Gems' code does.
At grazing half vectors (cos α → 0) P_H → 0; the double `where` keeps value and gradient
finite (0) there and at L = −V, where there is no half vector.
"""

from __future__ import annotations

import jax.numpy as jnp

from ..vectors import dot

__all__ = ["F0_SKIN", "specular"]

F0_SKIN = 0.028


def specular(N, L, V, roughness, rho_s, F0=F0_SKIN):
    """ρ_s (N·L) P_H F / |L + V|² per texel: `(...)` from `N (..., 3)` and unit `L`, `V`.

    **Arguments:** `roughness` m (> 0), `rho_s` the specular intensity, `F0` Schlick's
    reflectance at normal incidence.
    """
    h = L + V
    hh = dot(h, h)
    has_h = hh > 1e-12
    H = h / jnp.sqrt(jnp.where(has_h, hh, 1.0))[..., None]
    cos_l = dot(N, L)
    cos_a = dot(N, H)
    ok = has_h & (cos_a > 1e-4) & (cos_l > 0)
    c = jnp.where(ok, cos_a, 1.0)
    c2 = c * c
    m2 = roughness * roughness
    P_H = jnp.exp(-(1.0 - c2) / (c2 * m2)) / (m2 * c2 * c2)
    F = F0 + (1.0 - F0) * (1.0 - jnp.clip(dot(H, L), 0.0, 1.0)) ** 5
    value = rho_s * cos_l * P_H * F / jnp.where(has_h, hh, 1.0)
    return jnp.where(ok, value, 0.0)
