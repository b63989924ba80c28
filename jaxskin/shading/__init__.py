"""Shading models: `blinn` (eq. 4.12 with melanin and blood), `lafortune` (eq. 4.15–4.16),
`kelemen` (the specular term of skin and cosmetic layers, Huang et al. eq. 5)."""

from . import blinn, kelemen, lafortune

__all__ = ["blinn", "kelemen", "lafortune"]
