"""The fitted keys: `--fit`'s keys checked against a scene, and each key's transform between
its value and the unconstrained coordinate the optimiser moves."""

from __future__ import annotations

import dataclasses
import difflib
import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np

from jaxskin.io import InputError
from jaxskin.scene import LAYER_SCHEMA, SCHEMA, SKIN_MAPS, Scene

# A map key → the scalar it multiplies (the biophysical model's maps go here too). Layer
# maps, `layer.NAME.map`, multiply `layer.NAME.thickness_mm`.
MAP_SCALARS = {k: scalar for k, (scalar, _) in SKIN_MAPS.items()}
# Pairs of keys that trade off against each other in an image (warned about when fitted
# together): exact scale ambiguities and near ones.
DEGENERATE = {
    frozenset({"camera.exposure", "light.intensity"}):
        "exposure and light intensity both scale the image (exactly, with light.ambient)",
    frozenset({"camera.exposure", "light.ambient"}):
        "exposure and ambient light both scale the image (exactly, with light.intensity)",
    frozenset({"light.intensity", "material.melanin"}):
        "albedo against light intensity: melanin darkens much as less light does",
    frozenset({"light.intensity", "material.blood"}):
        "albedo against light intensity: blood darkens much as less light does",
    frozenset({"light.intensity", "skin.melanin"}):
        "albedo against light intensity: melanin darkens much as less light does",
    frozenset({"camera.exposure", "skin.melanin"}):
        "albedo against exposure: melanin darkens much as a lower exposure does",
}


@dataclasses.dataclass(frozen=True)
class FitKey:
    """One fitted value: `key` (a `Scene.params` key or a map key), `kind` (`"scalar"`,
    `"vector"`, `"map"` or `"lafortune"`: the lobes, ρd and n kept positive), its bounds
    `lo`, `hi` (None: free) and, for a map, the scalar it multiplies and its transform
    (`"sigmoid"`: in [0, hi/scalar], log-like near 0)."""

    key: str
    kind: str
    lo: float | None = None
    hi: float | None = None
    scalar: str | None = None
    transform: str | None = None

    @property
    def span(self) -> float:
        """hi − lo of the key's range (1 for a key without one)."""
        return float(self.hi - self.lo) if self.lo is not None else 1.0


def map_keys(scene: Scene) -> dict[str, str]:
    """The map keys a scene has, each → the scalar it multiplies."""
    if scene.config.spectral is None:
        return {}
    out = {f"layer.{layer.name}.map": f"layer.{layer.name}.thickness_mm"
           for layer in scene.layers}
    out.update({k: s for k, s in MAP_SCALARS.items() if s in scene.params})
    return out


def schema(key: str):
    """The schema entry of a scene key, a layer's (`layer.NAME.FIELD`) included; None for
    a key the schema does not have."""
    parts = key.split(".")
    if len(parts) == 3 and parts[0] == "layer":
        return LAYER_SCHEMA.get(parts[2])
    return SCHEMA.get(key)


def fit_keys(scene: Scene, text: str, where: str = "--fit") -> tuple[FitKey, ...]:
    """`--fit KEY[,KEY...]` for `scene`, checked: every key known, differentiable and used by
    the scene's model; no key twice; no scalar with its own map (the pair has one scale).
    Warns (`warnings.warn`) about the pairs in `DEGENERATE`. `InputError` otherwise."""
    names = [k.strip() for k in text.split(",")]
    if not names or any(not k for k in names):
        raise InputError(f"expected KEY[,KEY...], got {text!r}", where)
    params, maps = scene.params, map_keys(scene)
    out = []
    for key in names:
        if names.count(key) > 1:
            raise InputError("this key is given twice", where, key=key)
        if key in maps:
            scalar = maps[key]
            if scalar in names:
                raise InputError(f"fit the map or its scalar '{scalar}', not both: the map "
                                 "multiplies it, so only their product is seen", where, key=key)
            spec = schema(scalar)
            out.append(FitKey(key, "map", spec.lo, spec.hi, scalar, "sigmoid"))
            continue
        spec = schema(key)
        if key == "material.lafortune" and key in params:
            out.append(FitKey(key, "lafortune"))
            continue
        if key not in params:
            fittable = list(params) + list(maps)
            layers = [layer.name for layer in scene.layers]
            layer = key.split(".")[1] if key.startswith("layer.") and key.count(".") >= 2 \
                else None
            # A layer the scene lacks: say so, rather than "not used by the material model".
            if layer is not None and layer not in layers:
                near = difflib.get_close_matches(key, fittable, n=1, cutoff=0.5)
                why = (f"names no layer of this scene (its layers: {', '.join(layers) or 'none'})"
                       + (f"; did you mean '{near[0]}'?" if near else ""))
            elif spec is not None and not spec.param:
                why = ("is not differentiable: it is static (it decides which stages run or "
                       "their sizes)")
            elif spec is not None:
                why = (f"is not used by this scene's material model "
                       f"({scene.values['material.model']!r})")
            elif key.endswith("_map") or key.endswith(".map"):
                why = "is not a map of this scene"
            else:
                near = difflib.get_close_matches(key, fittable, n=1, cutoff=0.5)
                why = "is unknown" + (f" (did you mean '{near[0]}'?)" if near else "")
            raise InputError(f"{why}; this scene's fittable keys: {', '.join(fittable)}",
                             where, key=key)
        if spec.kind == "vec3":
            out.append(FitKey(key, "vector"))
        else:
            out.append(FitKey(key, "scalar", spec.lo, spec.hi))
    keys = {k.key for k in out}
    pairs = dict(DEGENERATE)
    melanin = keys & {"skin.melanin", "skin.melanin_map"}
    thickness = {k for k in keys if k.startswith("layer.") and k.endswith(("thickness_mm",
                                                                          ".map"))}
    for a in melanin:
        for b in thickness:
            pairs[frozenset({a, b})] = ("melanin against thickness: more melanin and a "
                                        "thicker tinted layer both darken the skin")
    for pair, why in pairs.items():
        if pair <= keys:
            a, b = sorted(pair)
            warnings.warn(f"fitting {a} and {b} together: {why}; fix one of them (the fit "
                          "finds one of many equally good answers)", stacklevel=2)
    return tuple(out)


# --- the parameter transforms -------------------------------------------------------------

def map_unit(fk: FitKey, params: dict) -> float:
    """A map's fitting scale: its scalar's value (the schema's top when that is 0)."""
    value = float(params[fk.scalar])
    return value if value > 0 else float(fk.hi)


def to_z(fk: FitKey, value, unit: float = 1.0):
    """The coordinate the optimiser moves for `value` of `fk` (inverse of `from_z`); `unit`:
    a map's fitting scale (`map_unit`)."""
    if fk.kind == "lafortune":  # ρd and the exponents n positive (log), Cxy and Cz free
        return value._replace(diffuse=jnp.log(jnp.maximum(value.diffuse, 1e-6)),
                              n=jnp.log(jnp.maximum(value.n, 1e-6)))
    return _to_z_array(fk, value, unit)


def _to_z_array(fk: FitKey, value, unit: float = 1.0):
    """The unconstrained coordinate of a value (inverse of `from_z`), kept off the bounds
    so that it is finite: by 1e-3 of the range for a scalar, 1e-7 for a map (whose range,
    up to the schema's top in units of its scalar, is wide: 0.01 mm of 10 mm)."""
    x = np.asarray(value, np.float64)
    if fk.kind == "vector":
        return x
    lo, hi = (0.0, fk.hi / unit) if fk.kind == "map" else (fk.lo, fk.hi)
    eps = 1e-7 if fk.kind == "map" else 1e-3
    f = np.clip((x - lo) / (hi - lo), eps, 1 - eps)
    return np.log(f) - np.log1p(-f)


def start_scale(z) -> float:
    """The factor c a scalar's coordinate is fitted in (the solver sees c z): 4 f (1 − f)
    at its start, f = σ(z) its place in its range, so that a change of the solver's
    coordinate moves the value as much at the start as a change of z does mid-range. A
    start at a range's end (f held at 1e-3: `skin.melanin = 0`, a thickness of 0) has
    the sigmoid's slope near 0 there, and Levenberg–Marquardt's damping, the same for
    every coordinate, takes steps so small there that it stops at once, near the start
    (melanin 0.003 for a truth of 0.3)."""
    f = 1.0 / (1.0 + math.exp(-float(z)))
    return 4.0 * f * (1.0 - f)


def from_z(fk: FitKey, z, unit: float = 1.0):
    """The value of `fk` at the optimiser's coordinate `z` (inverse of `to_z`): in its bounds
    by a sigmoid, a Lafortune lobe's ρd and n by exp, a vector as it is."""
    if fk.kind == "lafortune":
        return z._replace(diffuse=jnp.exp(z.diffuse), n=jnp.exp(z.n))
    if fk.kind == "vector":
        return z
    lo, hi = (0.0, fk.hi / unit) if fk.kind == "map" else (fk.lo, fk.hi)
    return lo + (hi - lo) * jax.nn.sigmoid(z)

