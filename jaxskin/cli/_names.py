"""Output names: a scene's base name with its `-D` values (or their digest), and the
`--sweep`'s values and file suffixes."""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

from ..checks import read_instead
from ..io import InputError
from ..outputs import MAX_NAME, MAX_NAME_BYTES, check_name, slug
from ._terminal import warn

__all__ = ["base_name", "file_ending_named", "name_value", "parse_sweep", "reads_instead",
           "sweep_suffixes", "sweeps", "warn_repeated"]


def warn_repeated(overrides) -> None:
    """A warning per key given with -D more than once with different values: the last one
    is used, and the output names list each."""
    seen: dict[str, list[str]] = {}
    for item in overrides:
        key, value = (s.strip() for s in item.partition("=")[::2])
        seen.setdefault(key, []).append(value)
    for key, values in seen.items():
        if len({name_value(key, v) for v in values}) > 1:
            warn(f"-D {key} is given {len(values)} times ("
                 f"{', '.join(values)}): the last, {values[-1]}, is used")


def parse_sweep(text: str, sc):
    """`key=start:stop:count` over a scalar parameter of scene `sc` → (key, values); the
    ends are checked like `-D` values (finite, in the key's range)."""
    import numpy as np

    from ..scene import check_value

    key, sep, spec = text.partition("=")
    key = key.strip()
    parts = spec.split(":")
    try:
        start, stop, count = float(parts[0]), float(parts[1]), int(parts[2])
        ok = bool(sep) and len(parts) == 3
    except (ValueError, IndexError):
        ok = False
    if not ok:
        raise InputError(f"--sweep expects key=start:stop:count (count an integer), got "
                         f"{text!r}")
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise InputError(f"start and stop must be finite numbers, got {start:g} and {stop:g}",
                         f"--sweep {text}", key=key)
    if not 1 <= count <= 1000:
        raise InputError(f"count must be in [1, 1000], got {count}", f"--sweep {text}",
                         key=key)
    params = sc.params
    if not sweeps(sc, text):
        import difflib

        from ..scene import SCHEMA

        names = [k for k, v in params.items() if getattr(v, "ndim", 1) == 0]
        near = difflib.get_close_matches(key, names, n=1)
        hint = (f"did you mean '{near[0]}'?" if near and key not in SCHEMA
                else f"parameters: {', '.join(names)}")
        if key in SCHEMA and not SCHEMA[key].param:
            hint = ("it is a static setting (each value compiles its own program): render "
                    f"each value with -D {key}=VALUE instead")
        raise InputError(f"--sweep: '{key}' is not a scalar parameter of this scene; {hint}",
                         sc.source)
    layers = [layer.name for layer in sc.layers]
    for value in (start, stop):
        check_value(key, value, f"--sweep {text}", layers)
    return key, np.linspace(start, stop, count)


def sweeps(sc, text: str) -> bool:
    """Whether the --sweep `text`'s key is a scalar parameter of scene `sc`."""
    key = text.partition("=")[0].strip()
    return key in sc.params and getattr(sc.params[key], "ndim", 1) == 0


def file_ending_named(value: str) -> str:
    """A -D value that names a file with its ending written `_ending` (`maps/m.png` →
    `maps/m_png`: the name read `..._skin.melanin_image-m.png.png`), so that the name
    still tells `m.png` from `m.exr` and a preset `skin` from a file `skin.json`."""
    from ..outputs import FILE_SUFFIXES

    suffix = Path(value).suffix
    if suffix.lower() in FILE_SUFFIXES:
        return value[:-len(suffix)] + "_" + suffix[1:]
    return value


def base_name(sc, overrides, room: int = 16) -> str:
    """The scene's output name: its (checked) name, then `_<key>-<value>` per override (a
    digest of them when that is long), unless one of them is `name=...`: then that name
    alone (a user naming a comparison's images got `espresso_look_D-13e6f4956f9c.png`).
    `room`: the most characters the outputs add after it (an extension, `_normal.png`, a
    sweep's `_sweep-NN_KEY-VALUE.png`). `InputError` naming the scene's `name` when even
    the digest leaves no room."""
    named = [item for item in overrides if item.partition("=")[0].strip() == "name"]
    base = check_name(sc.name, f"-D {named[-1]}" if named else sc.source, key="name")
    last = {}  # a key given twice: its last value, which is the one used
    for item in overrides:
        key, _, value = (s.strip() for s in item.partition("="))
        last.pop(key, None)
        last[key] = value
    parts = [f"{slug(key)}-{slug(file_ending_named(name_value(key, value)))}"
             for key, value in last.items()
             if key != "name" and not named]  # `-D name=X` names the outputs X, nothing added
    suffix = "_".join(parts)

    def too_long(text):  # with `room` added, in characters and in UTF-8 bytes
        return (len(text) > MAX_NAME - room
                or len(text.encode("utf-8", "surrogatepass")) > MAX_NAME_BYTES - room)

    # many overrides, or a long name: a digest keeps runs apart and names short
    if len(suffix) > 120 or (suffix and too_long(f"{base}_{suffix}")):
        used = "\0".join(f"{key}={name_value(key, value)}" for key, value in last.items())
        suffix = "D-" + hashlib.sha1(used.encode()).hexdigest()[:12]
    full = f"{base}_{suffix}" if suffix else base
    if too_long(full):
        raise InputError(f"the scene's name is {len(base)} characters; with what this run "
                         f"adds to it ({len(full) - len(base) + room} more: the -D values, "
                         "the sweep's values, the extension) the output names would be over "
                         f"{MAX_NAME} characters or {MAX_NAME_BYTES} bytes: shorten it (or "
                         "-D name=...)", f"-D {named[-1]}" if named else sc.source, key="name")
    return full


def name_value(key: str, value: str) -> str:
    """A -D value as output names spell it: a number in its shortest exact form, so that
    `-D k=0.1`, `k=1e-1` and `k=0.10` (one render) name one file; `512.0` and `512` both
    `512`; a list of numbers as its numbers joined by `_` (`0,60,0` and `[0, 60, 0]`
    alike). Anything else as given."""
    from ..scene import parse_override

    def short(x) -> str:
        text = repr(float(x) + 0.0)  # -0.0 + 0.0 is 0.0: `=-0` named the file `k--0`
        return text[:-2] if text.endswith(".0") else text

    def number(x) -> bool:
        return isinstance(x, (int, float)) and not isinstance(x, bool)

    try:
        return short(float(value))
    except ValueError:
        pass
    parsed = parse_override(f"{key}={value}")[1]
    if isinstance(parsed, list) and parsed and all(number(x) for x in parsed):
        return "_".join(short(x) for x in parsed)
    return value


def reads_instead(sc, item: str, overrides) -> str:
    """`"; it reads KEY"` for an unused `-D` or `--sweep` item whose key's twin scene `sc`
    reads (`checks.read_instead`), else `""`: the end of the warning's parenthesis."""
    other = read_instead(sc, item, overrides)
    return f"; it reads {other}" if other else ""


def sweep_suffixes(sweep, ext: str) -> list[str]:
    """What a sweep's files add to the scene's output name: `_sweep-NN_KEY-VALUE.EXT` per
    value (none without a sweep)."""
    if not sweep:
        return []
    (key, values), = sweep
    width = max(2, len(str(len(values))))
    # Six significant digits, more where two values would read alike (0.1:0.1000002:3 would
    # name three files 0.1), up to the float's own shortest form.
    values = [float(v) + 0.0 for v in values]  # -0.0 + 0.0 is 0.0 (not named --0)
    digits = next((d for d in range(6, 17) if len({f"{v:.{d}g}" for v in values})
                   == len(set(values))), 17)
    return [f"_sweep-{i + 1:0{width}d}_{slug(key)}-{slug(f'{v:.{digits}g}')}.{ext}"
            for i, v in enumerate(values)]

