"""What `render(config, params)` is given, checked before it traces: the config's type, the
params' keys (a misspelt key would be ignored, its gradient 0), shapes, ranges and maps, and
one float dtype for them all. Mistakes here would otherwise render silently wrong or fail
deep inside with another name."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .scene import LAYER_SCHEMA, SCHEMA, SKIN_MAPS, SceneConfig, param_keys

__all__ = ["check_call", "check_maps", "check_ranges", "known_keys", "strong"]


def strong(params: dict) -> dict:
    """The params as arrays of one float dtype, the widest among the arrays' (float32 when
    there are none). Python numbers and lists become arrays: a Python float traces as a
    weakly typed value, a second program for `render`'s jitted core (0.7-0.8 s on the 32²
    hand) where a new array value reuses the first, and a list would fail inside
    (`light.direction`). One dtype: a single float64 value among float32 ones makes the
    cosmetics model's branches disagree (a TypeError from `lax.switch`)."""
    def plain(v):
        return type(v) in (list, tuple) or (isinstance(v, (int, float))
                                            and not isinstance(v, bool))

    leaves = [leaf for k, v in params.items() if not plain(v)
              for leaf in jax.tree_util.tree_leaves(v)]
    floats = [jnp.result_type(leaf) for leaf in leaves
              if jnp.issubdtype(jnp.result_type(leaf), jnp.floating)]
    dtype = jnp.result_type(*floats) if floats else jnp.float32

    def cast(leaf):
        return leaf if jnp.result_type(leaf) == dtype else jnp.asarray(leaf, dtype)

    return {k: jnp.asarray(v, dtype) if plain(v) else jax.tree_util.tree_map(cast, v)
            for k, v in params.items()}


def check_call(config, params) -> None:
    """What `render` takes, checked where a mistake would otherwise render silently wrong
    (a misspelt key is ignored, its gradient 0) or fail deep inside with another name."""
    if not isinstance(config, SceneConfig):
        hint = " (pass scene.config)" if hasattr(config, "config") else ""
        raise TypeError(f"expected a SceneConfig{hint}, got {type(config).__name__}")
    if not isinstance(params, dict):
        raise TypeError(f"expected the params dict (scene.params), got {type(params).__name__}")
    known, layers, required = known_keys(config)
    unknown = sorted(k for k in params if k not in known)
    if unknown:
        import difflib

        near = difflib.get_close_matches(unknown[0], sorted(known), n=1, cutoff=0.6)
        raise ValueError(f"params: unknown key {unknown[0]!r}"
                         + (f" (did you mean {near[0]!r}?)" if near else "")
                         + (f" and {len(unknown) - 1} more" if len(unknown) > 1 else "")
                         + f"; this scene's layers: {', '.join(layers) or 'none'}")
    missing = [k for k in required if k not in params]
    if missing:  # a bare KeyError from deep inside before
        raise ValueError(f"params: missing key{'s' * (len(missing) > 1)} "
                         f"{', '.join(map(repr, missing[:4]))}"
                         + (f" and {len(missing) - 4} more" if len(missing) > 4 else "")
                         + "; the scene's model needs every key of scene.params: start from "
                         "it, e.g. scene.params | {key: value}")
    for key, value in params.items():  # a scalar of another shape failed deep inside
        want = _shape(known[key])
        if want is not None and tuple(np.shape(value)) != want:
            what = "a number" if want == () else "a 3-vector"
            raise ValueError(f"params[{key!r}]: expected {what} (shape {want}), got shape "
                             f"{tuple(np.shape(value))}; for several values at once, "
                             "jax.vmap over render (as --sweep does)")


def check_ranges(params: dict, specs: dict) -> None:
    """Concrete scalars and `light.direction` in `params` checked against their scene keys'
    ranges (`specs`: key → its scene key, `known_keys`), as `load_scene` checks them: out
    of range the models give unphysical numbers without an error (a negative thickness:
    pixels of −2e19; a zero light direction: NaN). Traced values
    (inside jit, grad, vmap) cannot be checked here."""
    for key, value in params.items():
        spec = specs.get(key)
        if spec is None or isinstance(value, jax.core.Tracer):
            continue
        v = np.asarray(value)
        if v.dtype == np.bool_:  # True would render as 1.0: a slip, not a number
            raise ValueError(f"params[{key!r}]: expected a number, got {value!r}")
        if not np.issubdtype(v.dtype, np.floating):
            v = v.astype(np.float64)
        if spec.kind == "vec3":
            with np.errstate(over="ignore", under="ignore", invalid="ignore"):
                squares = np.sum(v * v, dtype=v.dtype)
            # normalised in its own dtype, subnormals flushed (XLA): its squares' sum must
            # be a normal number, or the direction is NaN ([0, 0, 1e-30] in float32)
            if not (np.all(np.isfinite(v)) and np.isfinite(squares)
                    and squares >= np.finfo(v.dtype).tiny):
                raise ValueError(f"params[{key!r}]: expected a finite, non-zero 3-vector whose "
                                 f"length {v.dtype} holds (between about "
                                 f"{np.sqrt(np.finfo(v.dtype).tiny):.0e} and "
                                 f"{np.sqrt(np.finfo(v.dtype).max):.0e}), got {v.tolist()}")
        # the ends rounded as the value is: float32(0.1) is above the float64 0.1, so a
        # scene at a range end would fail here otherwise; NaN fails too
        elif not (v.dtype.type(spec.lo) <= v <= v.dtype.type(spec.hi)):
            raise ValueError(f"params[{key!r}]: must be in [{spec.lo:g}, {spec.hi:g}] (the "
                             f"scene key's range), got {float(v):.6g}")


@functools.lru_cache(maxsize=32)
def known_keys(config: SceneConfig) -> tuple[dict, list, list]:
    """The params keys `config` may take (every differentiable scene key, the maps, the
    lobes, its layers' keys), each with its scene key's spec (its kind, so the shape it must
    have, and its range; None: a map or the lobes, checked elsewhere), its layers' names,
    and the keys it needs (`scene.param_keys`): once per configuration."""
    layers = [] if config.spectral is None else [layer.name for layer in config.spectral.layers]
    known = {k: spec for k, spec in SCHEMA.items() if spec.param}
    known |= dict.fromkeys([*SKIN_MAPS, "material.lafortune"]
                           + [f"layer.{n}.map" for n in layers])
    known |= {f"layer.{n}.{a}": spec for n in layers for a, spec in LAYER_SCHEMA.items()}
    skin = "nist" if config.spectral is None else config.spectral.skin
    return known, layers, param_keys(config.material, skin, layers)


def _shape(spec) -> tuple | None:
    """The shape a param of scene key `spec` must have (None: a map or the lobes)."""
    return None if spec is None else {float: (), "vec3": (3,)}.get(spec.kind)


def check_maps(params, arrays) -> None:
    """Per-texel maps in `params` must have the texture's shape: a map of another size was
    read at clamped indices, the makeup on the wrong texels."""
    shape = tuple(arrays["mask"].shape)
    for key, value in params.items():
        if key.endswith("_map") or key.endswith(".map"):
            if tuple(jnp.shape(value)) != shape:
                raise ValueError(f"params[{key!r}]: expected a texture-space map of shape "
                                 f"{shape} (texture.size), got {tuple(jnp.shape(value))}")
