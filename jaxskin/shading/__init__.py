"""Shading models. `lafortune`: the Lafortune BRDF (Bando 2001 eq. 4.15)."""

from . import lafortune

__all__ = ["lafortune"]
