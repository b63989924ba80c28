"""Writing TOML, which the standard library reads but does not write (the editor's Save,
`scene_writer` for fit-image).

A scene document holds tables, strings, booleans, integers, floats (finite), arrays of
those and arrays of tables (`[[layer]]`, `[[fields.edit]]`): what this writes. Floats are
written with `repr`, which reads back as the same float, so a saved scene's values are
exactly the editor's.
"""

from __future__ import annotations

import json
import math

__all__ = ["dumps", "value_text"]


def value_text(v) -> str:
    """One TOML value: `0.5`, `true`, `"skin"`, `[0.0, 0.0, 1.0]`, `{vertex = 3, …}`."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"TOML scene values must be finite, got {v!r}")
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)  # its escapes (\" \\ \n \uXXXX) are TOML's too
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(value_text(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(k)} = {value_text(x)}" for k, x in v.items()) + "}"
    raise TypeError(f"cannot write {type(v).__name__} as a TOML value")


def _key(k: str) -> str:
    return k if k.replace("_", "").replace("-", "").isalnum() and k.isascii() else json.dumps(k)


def _is_tables(v) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def dumps(doc: dict) -> str:
    """`doc` as TOML text that `tomllib.loads` reads back equal to `doc`."""
    lines: list[str] = []
    _table(doc, [], lines, header=None)
    return "\n".join(lines).strip() + "\n"


def _table(table: dict, path: list[str], lines: list[str], header: str | None) -> None:
    if header is not None:
        lines += ["", header]
    for k, v in table.items():
        if not isinstance(v, dict) and not _is_tables(v):
            lines.append(f"{_key(k)} = {value_text(v)}")
    for k, v in table.items():
        name = ".".join(_key(p) for p in [*path, k])
        if isinstance(v, dict):
            _table(v, [*path, k], lines, f"[{name}]")
        elif _is_tables(v):
            for item in v:
                _table(item, [*path, k], lines, f"[[{name}]]")
