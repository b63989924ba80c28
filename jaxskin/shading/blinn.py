"""Blinn shading with melanin and blood (Bando 2001 eq. 4.12–4.14, 5.7, Table 5.1).

    c_j = I_ambient r_ambient,j + I_light r_diffuse,j cos θ + I_light r_specular cos^n γ
    r_diffuse,j = r_base,j − k_melanin a_melanin,j − k_blood a_blood,j,  r_ambient = r_diffuse

cos θ = N·L (clamped at 0), cos γ = N·H with H = (L + V)/|L + V|; the specular term is
max(0, N·H)^n, only where the surface faces the light. The power is exp(n log ·) behind a
double `where`, so gradients stay finite at grazing light and for shininess up to 1e4.
"""

from __future__ import annotations

import jax.numpy as jnp

from .lafortune import positive_power

__all__ = ["A_BLOOD", "A_MELANIN", "R_BASE", "shade", "skin_colour"]

R_BASE = (0.97, 0.87, 0.67)
A_MELANIN = (0.69, 0.71, 0.90)
A_BLOOD = (0.00, 0.24, 0.24)


def skin_colour(melanin, blood):
    """r_diffuse (eq. 5.7): `(..., 3)` from k_melanin and k_blood (0 to 1 in the paper)."""
    melanin, blood = jnp.asarray(melanin), jnp.asarray(blood)
    dtype = jnp.result_type(melanin, blood, jnp.float32)
    base, a_m, a_b = (jnp.asarray(c, dtype) for c in (R_BASE, A_MELANIN, A_BLOOD))
    return base - melanin[..., None] * a_m - blood[..., None] * a_b


def shade(N, L, V, melanin, blood, specular, shininess, ambient=0.3, light=0.7):
    """Eq. 4.12 per texel. `N (..., 3)` unit normals; `L`, `V` unit vectors to the light
    and the viewer (broadcastable). **Returns:** colour `(..., 3)`."""
    r = skin_colour(melanin, blood)
    cos_t = jnp.sum(N * L, axis=-1)
    h = L + V
    hh = jnp.sum(h * h, axis=-1, keepdims=True)
    ok = hh > 0  # L = −V: no half vector, no highlight
    H = jnp.where(ok, h / jnp.sqrt(jnp.where(ok, hh, 1.0)), 0.0)
    cos_g = jnp.where(cos_t > 0, jnp.sum(N * H, axis=-1), 0.0)
    spec = positive_power(cos_g, shininess)
    return (ambient * r + light * r * jnp.maximum(cos_t, 0.0)[..., None]
            + light * specular * spec[..., None])
