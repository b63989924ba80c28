"""JSON documents: any JSON file (`read_json`, `write_json`), Lafortune BRDF files and
calibrated material files."""

from __future__ import annotations

import dataclasses
import difflib
import json
import math
from pathlib import Path

import numpy as np

from ..io import InputError, atomic_write
from ._tables import WAVELENGTH_RANGE_NM, is_measurement_table
from ._text import read_text

# S and K of a material file above this (per mm) are refused: cosmetics measure 1e-3 to 1e5, and
# the float32 render of 1e300 (or of 1e37 with its scales at 100) is NaN, a black image.
MAX_SK_PER_MM = 1e9


def read_json(path, what: str):
    """A JSON document; `InputError` (with the line) if missing or malformed. `what` names
    the kind of file in the messages (e.g. 'material file')."""
    path = Path(path)
    text = read_text(path, expected=f"a JSON {what}")
    try:
        return json.loads(text, parse_constant=_no_constant)
    except json.JSONDecodeError as e:
        raise InputError(f"not a JSON {what} ({e.msg})", path, e.lineno) from None
    except ValueError as e:  # NaN, Infinity
        raise InputError(f"not a JSON {what} ({e})", path) from None
    except RecursionError:
        raise InputError(f"not a JSON {what} (nested too deeply)", path) from None


def _no_constant(name):
    raise ValueError(f"{name} is not a JSON number")


def write_json(doc, path) -> None:
    """Write `doc` as indented JSON, atomically; a NaN or infinity anywhere is a `ValueError`
    (a bug: callers check their numbers first), so no file ever holds one."""
    text = json.dumps(doc, indent=1, allow_nan=False)
    with atomic_write(path, "w") as fh:
        fh.write(text + "\n")


# ---------------------------------------------------------------- Lafortune BRDF files


def read_lafortune(path, dtype=None):
    """A Lafortune material file (what `jaxskin fit-brdf` writes) as `lafortune.Lafortune`
    (float32 unless `dtype`); `InputError` names the key that is wrong."""
    import jax.numpy as jnp

    from ..shading import lafortune

    return lafortune.from_json(read_json(path, "BRDF file"), Path(path),
                               jnp.float32 if dtype is None else dtype)


def write_lafortune(p, path, **extra) -> None:
    """Write Lafortune lobes `p` (and `extra` keys, e.g. fit statistics) as a material file."""
    from ..shading import lafortune

    write_json(lafortune.to_json(p, **extra), path)


# ---------------------------------------------------------------- calibrated materials

EXTRAPOLATE = ("hold", "linear")


@dataclasses.dataclass(frozen=True)
class MaterialFile:
    """A calibrated material as stored: `S`, `K (n,)` per mm at `wavelength_nm (n,)`, and
    how it may be extended beyond them (`extrapolate`: "hold", "linear" or None)."""

    path: Path
    name: str
    wavelength_nm: np.ndarray
    S: np.ndarray
    K: np.ndarray
    extrapolate: str | None


def _calibrate_first(path: Path) -> str:
    return f"run 'jaxskin calibrate {path} -o DIR' first and give the DIR/<name>.json it writes"



# The other keys `jaxskin calibrate` writes (a misspelt required key is looked for among
# the keys that are none of these).
_MATERIAL_OTHER_KEYS = ("name", "model", "extrapolate", "identifiable", "rmse", "fit")


def read_material(path) -> MaterialFile:
    """Read and check a material JSON (what `jaxskin calibrate` writes); a measurement CSV
    given instead is refused with a line saying to calibrate it first."""
    path = Path(path)
    if path.suffix.lower() == ".csv" and path.is_file():
        raise InputError(f"a CSV file, expected a material JSON: {_calibrate_first(path)}",
                         path)
    try:
        doc = read_json(path, "material file")
    except InputError:
        if is_measurement_table(path):  # a measurement saved as .txt, .dat, ...
            raise InputError("a measurement table (a wavelength column), expected a material "
                             f"JSON: {_calibrate_first(path)}", path) from None
        raise
    if not isinstance(doc, dict):
        raise InputError("expected a JSON object (a material written by jaxskin calibrate)",
                         path)
    model = doc.get("model", "kubelka-munk")
    if model == "lafortune" or "lobes" in doc:  # a fit-brdf output given by mistake
        raise InputError("a Lafortune BRDF (written by jaxskin fit-brdf; it goes in "
                         "material.brdf), expected a Kubelka-Munk material (written by jaxskin "
                         "calibrate)", path, key="model" if "model" in doc else None)
    if model != "kubelka-munk":  # another model is refused, not read as Kubelka-Munk
        raise InputError(f"expected \"kubelka-munk\" (or no model key), got {model!r}", path,
                         key="model")
    arrays = {}
    known = ("wavelength_nm", "S_per_mm", "K_per_mm")
    if "S_per_mm" not in doc and "S_film" in doc:  # calibrated without the film's thickness
        raise InputError("S and K of a film of unknown thickness (S_film, K_film: S*X and K*X, "
                         "calibrated without the film's thickness): a scene needs them per mm; "
                         "calibrate again with --thickness MM (or a '# thickness_mm:' line) "
                         "to render it", path, key="S_film")
    for k in known:
        if k not in doc:  # a hand edit may have renamed it (S_per_mn): name both
            others = [o for o in doc if o not in known and o not in _MATERIAL_OTHER_KEYS]
            near = difflib.get_close_matches(k, others, n=1, cutoff=0.6)
            hint = f" (is {near[0]!r} a misspelling of it?)" if near else ""
            raise InputError(f"missing{hint}; a material written by jaxskin calibrate has "
                             f"{', '.join(known)}", path, key=k)
        v = doc[k]
        if not isinstance(v, list) or len(v) < 2:
            raise InputError("expected a list of at least two finite numbers (a material "
                             "written by jaxskin calibrate)", path, key=k)
        for i, x in enumerate(v):
            if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
                raise InputError(f"entry {i} is {json.dumps(x)}: expected a finite number",
                                 path, key=k)
        arrays[k] = np.asarray(v, np.float64)
    wl, S, K = arrays["wavelength_nm"], arrays["S_per_mm"], arrays["K_per_mm"]
    if not (len(wl) == len(S) == len(K)):
        raise InputError(f"wavelength_nm, S_per_mm and K_per_mm have lengths {len(wl)}, "
                         f"{len(S)}, {len(K)}; expected equal", path, key="S_per_mm")
    if np.any(np.diff(wl) <= 0):
        raise InputError("wavelengths must increase", path, key="wavelength_nm")
    lo, hi = WAVELENGTH_RANGE_NM
    if wl[0] < lo or wl[-1] > hi:
        raise InputError(f"wavelengths {wl[0]:g}-{wl[-1]:g} must lie in {lo:g}-{hi:g} nm (µm "
                         "given? write nm)", path, key="wavelength_nm")
    for k, v in (("S_per_mm", S), ("K_per_mm", K)):
        if np.any(v <= 0):
            i = int(np.flatnonzero(v <= 0)[0])
            raise InputError(f"must be > 0 at every band; entry {i} ({wl[i]:g} nm) is "
                             f"{v[i]:g}", path, key=k)
        if np.any(v > MAX_SK_PER_MM):  # the float32 render overflowed to a black image
            i = int(np.flatnonzero(v > MAX_SK_PER_MM)[0])
            raise InputError(f"must be at most {MAX_SK_PER_MM:g} per mm at every band "
                             f"(cosmetics: about 1e-3 to 1e5); entry {i} ({wl[i]:g} nm) is "
                             f"{v[i]:g}", path, key=k)
    extrapolate = doc.get("extrapolate")
    if extrapolate is not None and extrapolate not in EXTRAPOLATE:
        raise InputError(f"expected \"hold\" or \"linear\", got {extrapolate!r}", path,
                         key="extrapolate")
    name = doc.get("name", path.stem)
    return MaterialFile(path, str(name), wl, S, K, extrapolate)


