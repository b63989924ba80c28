"""Blinn shading with melanin and blood (Bando 2001 eq. 4.12–4.14, §5.3).

    c_j = I_ambient r_j + I_light r_j cos θ + I_light r_specular cos^n γ          (4.12)

cos θ = N·L (clamped at 0), cos γ = N·H with H = (L + V)/|L + V|; the specular term is
max(0, N·H)^n, only where the surface faces the light. The power is exp(n log ·) behind a
double `where`, so gradients stay finite at grazing light and for shininess up to 1e4.

**Units** (the same for all three material models): `c` is linear sRGB, in units where a
white Lambertian surface facing the light gives I_ambient + I_light (1.0 at the defaults
0.3 + 0.7); I_light is the parallel light's irradiance at normal incidence, I_ambient a
uniform irradiance that reaches every point. `r_j` is the skin's diffuse albedo. The
camera's exposure and the sRGB encoding come after (`jaxskin.render`).

**Skin colour: where we depart from eq. 5.7.** The paper (Table 5.1, "no physical or
biological meaning") uses a plane in RGB,

    r_diffuse,j = r_base,j − k_melanin a_melanin,j − k_blood a_blood,j
    r_base = (0.97, 0.87, 0.67), a_melanin = (0.69, 0.71, 0.90), a_blood = (0, 0.24, 0.24)

which makes blue negative above k_melanin ≈ 0.6 (0.67 − 0.9 k − 0.24 k_blood) and turns
dark skin rust-orange with blue clipped. The paper's source for the plane (Tsumura et al.)
finds it in *optical density*, −ln r, where absorbers add (Beer–Lambert); we use that form:

    r_j = r_base,j · exp(−k_melanin A_melanin,j − k_blood A_blood,j)      (linear sRGB)

so every channel stays in (0, r_base] and darkens monotonically. `data/make_skin_colour.py`
derives the constants from published data: A_melanin is the melanin axis of the NIST skin
spectra (the first principal axis of their densities, 98 % of the variance), its length
set by Jacques' darkest epidermis (43 % melanosomes, μa = 6.6e11 λ^−3.33 /cm, 60 µm, two
passes: red density 1.56); A_blood is Table 5.1's a_blood / r_base (the paper's blood,
equal to eq. 5.7 to first order); r_base puts the paper's default skin (0.2, 0.5) at the
NIST subjects' mean colour. Over melanin and blood 0–1 the colour runs from CIELAB L* 81
to 31 with hue 50–66° and chroma 9–28 (light to dark brown).
"""

from __future__ import annotations

import jax.numpy as jnp

from ..vectors import dot
from .lafortune import positive_power

__all__ = ["A_BLOOD", "A_MELANIN", "R_BASE", "shade", "skin_colour"]

# Linear sRGB albedo and optical densities per unit k (data/make_skin_colour.py).
R_BASE = (0.6812, 0.5747, 0.5025)
A_MELANIN = (1.5581, 2.2374, 2.9289)
A_BLOOD = (0.0000, 0.2759, 0.3582)


def skin_colour(melanin, blood):
    """The diffuse albedo r `(..., 3)`, linear sRGB, from k_melanin and k_blood (0–1):
    r_base · exp(−k_melanin A_melanin − k_blood A_blood) (module docstring)."""
    melanin, blood = jnp.asarray(melanin), jnp.asarray(blood)
    dtype = jnp.result_type(melanin, blood, jnp.float32)
    base, a_m, a_b = (jnp.asarray(c, dtype) for c in (R_BASE, A_MELANIN, A_BLOOD))
    return base * jnp.exp(-melanin[..., None] * a_m - blood[..., None] * a_b)


def shade(N, L, V, melanin, blood, specular, shininess, ambient=0.3, light=0.7):
    """Eq. 4.12 per texel, linear. `N (..., 3)` unit normals; `L`, `V` unit vectors to the
    light and the viewer (broadcastable); `ambient`, `light`: irradiances (module
    docstring). **Returns:** colour `(..., 3)`."""
    r = skin_colour(melanin, blood)
    cos_t = dot(N, L)
    h = L + V
    hh = dot(h, h, keepdims=True)
    ok = hh > 0  # L = −V: no half vector, no highlight
    H = jnp.where(ok, h / jnp.sqrt(jnp.where(ok, hh, 1.0)), 0.0)
    cos_g = jnp.where(cos_t > 0, dot(N, H), 0.0)
    spec = positive_power(cos_g, shininess)
    return (ambient * r + light * r * jnp.maximum(cos_t, 0.0)[..., None]
            + light * specular * spec[..., None])
