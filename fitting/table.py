"""Numeric CSV tables with `# key: value` comments, read with one-line errors.

Both measurement formats (spectroradiometer, BRDF samples) are this: optional comment lines,
a header, rows of finite numbers. Every problem is an `InputError` naming the file, the line
and the column.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from jaxskin.io import InputError

__all__ = ["Table", "read_table"]


@dataclasses.dataclass(frozen=True)
class Table:
    """`header` names, `data (rows, columns)` floats, `lines` (file line of each row),
    `header_line`, `meta` ({key: (value, line)} from `# key: value` before the header)."""

    path: Path
    header: list[str]
    header_line: int
    data: np.ndarray
    lines: list[int]
    meta: dict[str, tuple[str, int]]

    def column(self, name: str) -> np.ndarray:
        return self.data[:, self.header.index(name)]

    def error(self, message: str, row: int | None = None, column: str | None = None):
        """An `InputError` at data row `row` (or the header when None) and `column`."""
        line = self.header_line if row is None else self.lines[row]
        return InputError(message, self.path, line, column)


def read_table(path, expected_header: str, min_rows: int = 1) -> Table:
    """Read `path`; `expected_header` is shown when the header is missing."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise InputError("no such file", path) from None
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"cannot read as UTF-8 text ({e.__class__.__name__})", path) from None

    meta: dict[str, tuple[str, int]] = {}
    header, header_line, rows = None, 0, []
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#"):
            if header is None and ":" in line:
                key, value = line[1:].split(":", 1)
                meta[key.strip().lower()] = (value.strip(), number)
            continue
        cells = [c.strip() for c in line.split(",")]
        if header is None:
            header, header_line = cells, number
        else:
            rows.append((number, cells))
    if header is None:
        raise InputError(f"no header line; expected '{expected_header}'", path)
    for i, name in enumerate(header):
        if name in header[:i]:
            raise InputError("column appears twice", path, header_line, name)
    if len(rows) < min_rows:
        rows_ = "row" if min_rows == 1 else "rows"
        raise InputError(f"needs at least {min_rows} data {rows_}, found {len(rows)}", path,
                         header_line)

    data = np.empty((len(rows), len(header)))
    for r, (number, cells) in enumerate(rows):
        if len(cells) != len(header):
            raise InputError(f"{len(cells)} cells where the header has {len(header)}", path,
                             number)
        for c, cell in enumerate(cells):
            try:
                value = float(cell)
            except ValueError:
                raise InputError(f"expected a number, got {cell!r}", path, number,
                                 header[c]) from None
            if not math.isfinite(value):
                raise InputError(f"expected a finite number, got {cell!r}", path, number,
                                 header[c])
            data[r, c] = value
    return Table(path, header, header_line, data, [n for n, _ in rows], meta)
