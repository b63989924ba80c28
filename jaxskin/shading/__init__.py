"""Shading models: `blinn` (eq. 4.12 with melanin and blood) and `lafortune` (eq. 4.15–4.16)."""

from . import blinn, lafortune

__all__ = ["blinn", "lafortune"]
