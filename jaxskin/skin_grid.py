"""The melanin × blood grid: small Blinn renders of one scene over k_melanin and k_blood
(the documentation's picture of `shading.blinn`'s skin colours; the gallery's grid)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from . import render
from .scene import load_scene

__all__ = ["skin_grid"]


def skin_grid(melanin, blood, scene="hand", size=80, overrides=()):
    """Renders `(len(blood), len(melanin), size, size, 3)`, display values, of `scene` with
    the Blinn material at each melanin (columns) and blood (rows); one vmapped program.

    **Arguments:** `melanin`, `blood`: values in [0, 1]; `scene`: a scene name or file;
    `size`: pixels across each render; `overrides`: more `-D key=value` strings.
    """
    sc = load_scene(scene, ["material.model=blinn", "view.mode=overview",
                            f"camera.size={size}", "camera.supersample=2", *overrides])
    m, b = np.meshgrid(np.asarray(melanin, np.float32), np.asarray(blood, np.float32))
    arrays = render.prepare(sc.config).arrays

    def one(mi, bi):
        params = {**sc.params, "material.melanin": mi, "material.blood": bi}
        return render.render_prepared(sc.config, params, arrays)

    images = jax.jit(jax.vmap(one))(jnp.asarray(m.ravel()), jnp.asarray(b.ravel()))
    return np.asarray(images).reshape(*m.shape, *images.shape[1:])
