"""Values as checked: `-D key=value` overrides, every value's type and range check (a
file's and an override's alike), and the number helpers the tables share."""

from __future__ import annotations

import difflib
import math
import re
import tomllib

from ..io import InputError
from ._schema import LAYER_SCHEMA, SCHEMA

# A number's point with no digit before it (.5) or after it (5.), where a number may stand:
# a 0 is put there (0.5, 5.0) before TOML reads it.
_POINT_ALONE = re.compile(r"(?:(?<=^)|(?<=[\s,\[+-]))(\.)(?=\d)|(?<=\d)(\.)(?![\d\w])")


def parse_override(item: str, flag: str = "-D"):
    """`(key, value)` of a `"key=value"` item, the value read as TOML (a bare word as a
    string); `InputError` naming `flag` without an `=`. Not checked against the schema."""
    if "=" not in item:
        raise InputError(f"expected {flag} key=value, got {item!r}")
    key, text = (s.strip() for s in item.split("=", 1))
    spec = SCHEMA.get(key)
    numeric = (spec.kind in (float, int, "vec2", "vec3") if spec is not None else
               key.startswith("layer.") and key.rsplit(".", 1)[-1] in LAYER_SCHEMA)
    if numeric:  # .5 and 5. as 0.5 and 5.0 (TOML wants digits on both sides of the point)
        text = _POINT_ALONE.sub(lambda m: "0." if m[1] else ".0", text)
    try:
        value = tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        value = text  # a bare word: a string
        if spec is not None and spec.kind in ("vec2", "vec3"):  # numbers with commas, as
            try:  # typed without brackets (camera.rotate=0,60,0, not a string); a
                items = tomllib.loads(f"v = [{text}]")["v"]  # scalar's 0,5 stays '0,5'
            except tomllib.TOMLDecodeError:
                items = []
            if len(items) > 1 and all(isinstance(c, (int, float)) and not isinstance(c, bool)
                                      for c in items):
                value = items
    return key, value


def material_overrides(overrides, flag: str) -> dict:
    """`-D layer.NAME.material=...` items: `{NAME: (value, item)}`, the last one given
    winning (a name that is no layer's is left for `check_value` to report)."""
    out = {}
    for item in overrides:
        k, v = parse_override(item, flag)
        parts = k.split(".")
        if len(parts) == 3 and parts[0] == "layer" and parts[2] == "material":
            out[parts[1]] = (v, f"{flag} {item}")
    return out


def check_value(key: str, value, where, layers=()):
    """`value` for `key`, checked as a scene file's or `-D`'s value is (type, range); an
    `InputError` naming `where` and the key otherwise. `layers`: the scene's layer names."""
    layers = tuple(layers)
    spec = SCHEMA.get(key)
    parts = key.split(".")
    if spec is None and len(parts) == 3 and parts[0] == "layer":
        if parts[1] not in layers:
            raise InputError(f"no layer named {parts[1]!r} (this scene's layers: "
                             f"{', '.join(layers) or 'none'})", where, key=key)
        spec = LAYER_SCHEMA.get(parts[2])
        if spec is None:
            raise InputError("a layer's value to set must be one of "
                             f"{', '.join([*LAYER_SCHEMA, 'material'])}", where, key=key)
    if key in ("fields.edit", "layer"):  # known tables, not "unknown key; did you mean ..."
        table = "[[fields.edit]]" if key == "fields.edit" else "[[layer]]"
        raise InputError(f"{table} tables are written in a scene file; they cannot be set as "
                         "one value", where, key=key)
    sections = {k.split(".")[0] for k in SCHEMA if "." in k} | {"fields", "layer"}
    if spec is None and len(parts) > 1 and parts[0] not in sections:
        near = difflib.get_close_matches(parts[0], sorted(sections), n=1, cutoff=0.5)
        fixed = ".".join([*near[:1], *parts[1:]])
        hint = (f"did you mean '{fixed}'?" if fixed in SCHEMA else f"did you mean [{near[0]}]?"
                if near else f"the tables are {', '.join(f'[{t}]' for t in sorted(sections))}")
        raise InputError(f"unknown table [{parts[0]}]; {hint}", where, key=key)
    if spec is None:
        near = difflib.get_close_matches(key, [*SCHEMA, "fields.edit", "layer"], n=1,
                                         cutoff=0.5)
        hint = f"; did you mean '{near[0]}'?" if near else f"; valid keys: {', '.join(SCHEMA)}"
        raise InputError(f"unknown key{hint}", where, key=key)
    kind = spec.kind
    if kind == "vec2":
        value = vector(value, key, where, n=2)
        if not all(spec.lo <= c <= spec.hi for c in value):
            raise InputError(f"each number must be in [{spec.lo:g}, {spec.hi:g}], got "
                             f"{list(value)!r}", where, key=key)
        return value
    if kind == "vec3":
        value = vector(value, key, where)
        if spec.param and key == "light.direction" and not any(value):
            raise InputError("the light direction must not be zero", where, key=key)
        if spec.param and not float32_direction(value):  # [0, 0, 1e-320], [1e200, 0, 1]
            raise InputError("expected a direction whose length float32 holds, between 1e-19 "
                             "and 1e19 (the render normalises it in float32, where this one "
                             f"is {'0' if max(map(abs, value)) < 1 else 'infinite'}), got "
                             f"{list(value)!r}", where, key=key)
        return value
    ok = isinstance(value, kind) and not (kind is not bool and isinstance(value, bool))
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        value, ok = float(value), True
    if not ok or (kind is float and not math.isfinite(value)):
        raise InputError(f"expected {'a finite number' if kind is float else kind.__name__}, "
                         f"got {value!r}{comma_hint(value) if kind is float else ''}", where,
                         key=key)
    if spec.choices is not None and value not in spec.choices:
        raise InputError(f"must be one of {', '.join(map(str, spec.choices))}; got {value!r}",
                         where,
                         key=key)
    if spec.lo is not None and not (spec.lo <= value <= spec.hi):
        raise InputError(f"must be in [{spec.lo:g}, {spec.hi:g}], got {value!r}", where, key=key)
    return value


def float32_direction(value) -> bool:
    """Whether the 3-vector `value` normalises in float32 as the render does it (`v / |v|`,
    `jnp.linalg.norm`): every number finite in float32 and the sum of their squares a
    finite normal float32 (XLA flushes subnormals to zero: a NaN direction otherwise)."""
    import numpy as np

    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        v = np.asarray(value, np.float64).astype(np.float32)
        squares = np.sum(v * v, dtype=np.float32)
    return bool(np.all(np.isfinite(v)) and np.isfinite(squares)
                and squares >= np.finfo(np.float32).tiny)


def finite_list(value, n: int, positive: bool = False) -> bool:
    """Whether `value` is a list of `n` finite numbers (all > 0 if `positive`)."""
    return isinstance(value, list) and len(value) == n and all(
        isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c)
        and (c > 0 or not positive) for c in value)


def vector(value, key, path, limit=None, n=3):
    """`value` as a tuple of `n` floats (a vector), with a magnitude of at most `limit`
    if given; `InputError` naming `path` and `key` otherwise."""
    if not finite_list(value, n):
        raise InputError(f"expected {('two', 'three')[n - 2]} finite numbers "
                         f"({('[x, y]', '[x, y, z]')[n - 2]}), got {value!r}", path, key=key)
    if limit is not None and math.hypot(*value) > limit + 1e-9:
        raise InputError(f"magnitude must be in [0, {limit:g}] (the paper's range), got "
                         f"{math.hypot(*value):.3g}", path, key=key)
    return tuple(float(c) for c in value)


def comma_hint(value) -> str:
    """A hint for a number written with a decimal comma (`-D skin.melanin=0,5`)."""
    if isinstance(value, str) and re.fullmatch(r"[+-]?\d*,\d+", value.strip()):
        return f" (a decimal comma? write {value.strip().replace(',', '.')})"
    return ""


def number(value, path, where, lo=None):
    """`value` as a finite float (at least `lo` if given); `InputError` otherwise."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(
            value) or (lo is not None and value < lo):
        bound = f" >= {lo:g}" if lo is not None else ""
        raise InputError(f"expected a finite number{bound}, got {value!r}{comma_hint(value)}",
                         path, key=where)
    return float(value)


def numbers(value, n, path, where, positive=False):
    """`value` as a tuple of `n` finite floats (each > 0 if `positive`); `InputError`
    otherwise."""
    if not finite_list(value, n, positive):
        raise InputError(f"expected {n} finite{' positive' if positive else ''} numbers, got "
                         f"{value!r}", path, key=where)
    return tuple(float(c) for c in value)
