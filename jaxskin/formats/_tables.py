"""CSV and TSV tables as instruments export them (`read_table`), and the checks of their
columns and readings that several readers share."""

from __future__ import annotations

import csv
import dataclasses
import math
import re
from pathlib import Path

import numpy as np

from ..io import InputError
from ._text import DELIMITERS, read_text, split_row

WAVELENGTH_RANGE_NM = (200.0, 3000.0)  # what a spectroradiometer can measure, generously
# The first column: wavelength_nm (the format's name) or what instrument software and
# spreadsheets write: "Wavelength", "Wavelength (nm)", "Wavelength nm", "wavelength/nm",
# "wavelength [µm]", "lambda", "λ", "wl", "nm", and in German, French, Spanish, Italian,
# Portuguese and Dutch ("Wellenlänge (nm)").
WAVELENGTH_HEADER = re.compile(
    r"(?i)(?:wave\s*length|wl|lambda|λ|wellenl(?:ä|ae|a)nge|longueur\s*d['’]?\s*onde"
    r"|longitud\s*de\s*onda|lunghezza\s*d['’]?\s*onda|comprimento\s*de\s*onda|golflengte)"
    r"(?:(?:\s*[_(\[/]\s*|\s+)(?P<unit>nm|um|µm|μm|micron|microns)\s*[)\]]?)?|nm")
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
DECIMAL_COMMA = re.compile(r"[+-]?\d*,\d+(?:[eE][+-]?\d+)?")
_THOUSANDS = re.compile(r"[1-9]\d{0,2}(?:,\d{3})+")  # 1,050: 1050, or 1.05 (µm)?
_NAMES = {"\t": "tab", ",": "comma", ";": "semicolon"}
# A reading column's header that says its unit is percent: `R_inf (%)`, `Cheek [%]`, `A %`;
# not a number's % (`Foundation 30%`, `Intralipid 2 %`: part of a name).
PERCENT_UNIT = re.compile(r"\s*[(\[]\s*%\s*[)\]]$|(?<![\d.\s])\s*%$")


def decimal_comma_note(example: str) -> str:
    """The note for a table read with decimal commas, quoting the first of them (the
    user's own data, not a fixed example that reads as if it were)."""
    return (f"numbers with a decimal comma ({example}) read with a point "
            f"({example.replace(',', '.')})")


@dataclasses.dataclass(frozen=True)
class Table:
    """`header` names, `data (rows, columns)` floats, `lines` (file line of each row),
    `header_line`, `meta` ({key: (value, line)} from `# key: value` before the header),
    `delimiter`."""

    path: Path
    header: list[str]
    header_line: int
    data: np.ndarray
    lines: list[int]
    meta: dict[str, tuple[str, int]]
    delimiter: str = ","
    decimal_comma: str = ""  # the first number written with a decimal comma, if any

    def column(self, name: str) -> np.ndarray:
        """The values of the column named `name`, `(rows,)`."""
        return self.data[:, self.header.index(name)]

    def error(self, message: str, row: int | None = None, column: str | None = None):
        """An `InputError` at data row `row` (or the header when None) and `column`."""
        line = self.header_line if row is None else self.lines[row]
        return InputError(message, self.path, line, column)


def header_row(line: str, first_column, other_column=None):
    """`(cells, delimiter)` if `line` is a table's header row (its first cell accepted by
    `first_column` and, with `other_column`, a later cell by that), else None; of several
    delimiters that fit, the one that gives the most cells. Raises `csv.Error`."""
    split = {d: split_row(line, d) for d in DELIMITERS}
    found = [d for d in DELIMITERS if first_column(split[d][0]) and (
        other_column is None or any(other_column(c) for c in split[d][1:]))]
    if not found:
        return None
    delimiter = max(found, key=lambda d: len(split[d]))
    return split[delimiter], delimiter


def read_table(path, first_column, expected_header: str, min_rows: int = 1,
               other_column=None, once: tuple[str, ...] = (), on_header=None,
               wavelength_first: bool = False, missing: bool = False) -> Table:
    """Read a numeric CSV table.

    **Arguments:**

    - `path`: the file.
    - `first_column`: a function telling whether a cell names the first column: the header
      is the first row whose first cell it accepts (and, with `other_column`, that has a
      later cell `other_column` accepts: a preamble line such as `Wavelength range,350`
      is not the header).
    - `expected_header`: shown when no header is found.
    - `min_rows`: the fewest data rows accepted.
    - `once`: `# key:` lines the caller reads: one given twice with another value is an
      error (which would count is a guess); other keys keep their first value.
    - `on_header`: called with `(header, meta, header line)` once the header is found,
      before any row is read (it may check the header and raise); returns the names of
      columns to skip (not parsed, not returned: standard deviations, counts, notes).
    - `wavelength_first`: the first column is wavelengths in nm: in a `;` or tab file,
      `1,050` (1050 nm, or 1.05 with a decimal comma?) is refused; `380,000` is 380 nm.
    - `missing`: an empty cell after the first column is a missing reading (NaN), not an
      error (spectra measured over different ranges in one table).

    **Returns:** a `Table`. **Raises:** `InputError` on anything malformed.
    """
    path = Path(path)
    # Instruments' Windows software writes Windows-1252 (µm, °, curly quotes in the header
    # and comments); a table's numbers read the same either way.
    text = read_text(path, fallback="cp1252")
    lines = text.splitlines()
    header, delimiter, header_line, meta = _find_header(
        path, lines, first_column, expected_header, other_column, once)
    for i, name in enumerate(header):
        if name == "":
            raise InputError(f"header cell {i + 1} is empty", path, header_line)
        if name in header[:i]:
            raise InputError("column appears twice", path, header_line, name)
    skipped = set(on_header(header, meta, header_line)) if on_header is not None else set()
    kept = [c for c, name in enumerate(header) if name not in skipped]
    rows, numbers, decimal_comma = _read_rows(path, lines, header, header_line, delimiter,
                                              kept, wavelength_first, missing)
    if len(rows) < min_rows:
        rows_ = "row" if min_rows == 1 else "rows"
        raise InputError(f"needs at least {min_rows} data {rows_}, found {len(rows)}", path,
                         header_line)
    header = [header[c] for c in kept]
    data = np.asarray(rows, np.float64).reshape(len(rows), len(header))
    return Table(path, header, header_line, data, numbers, meta, delimiter, decimal_comma)


def _find_header(path, lines, first_column, expected_header, other_column, once):
    """`(header cells, delimiter, header line, meta)`: the first of `lines` that
    `header_row` accepts, and the `# key: value` lines before it (a key in `once` given
    twice with another value is an `InputError`). With no header, an `InputError` that says
    what the row above the data began with (`_no_header`)."""
    meta: dict[str, tuple[str, int]] = {}
    first = None  # the last line before the data whose first cell is text: the header meant
    data_seen = False
    try:
        for number, raw in enumerate(lines, start=1):
            line = raw.strip()
            if not line:
                continue
            if not data_seen and not line.startswith("#"):
                cell = re.split(r"[,;\t]", line, maxsplit=1)[0].strip().strip('"')
                if _NUMBER.fullmatch(cell) or DECIMAL_COMMA.fullmatch(cell):
                    data_seen = True
                elif cell:
                    first = (number, cell)
            if line.startswith("#"):
                if ":" in line:
                    key, value = line[1:].split(":", 1)
                    key, value = key.strip().lower(), value.strip()
                    if key in once and key in meta and meta[key][0] != value:
                        raise InputError(f"'# {key}:' again, with another value than on line "
                                         f"{meta[key][1]} ({meta[key][0]!r}); keep one",
                                         path, number)
                    meta.setdefault(key, (value, number))
                continue
            row = header_row(line, first_column, other_column)
            if row is not None:
                header, delimiter = row
                return header, delimiter, number, meta
    except csv.Error as e:
        raise InputError(f"not CSV ({e})", path, number) from None
    raise _no_header(path, expected_header, first)


def _no_header(path, expected_header: str, first) -> InputError:
    """The error for a table with no header row; `first`: `(line, first cell)` of the last
    line before the data whose first cell is text (the header meant), or None."""
    seen = ""
    if first is not None:  # the row above the data, not a preamble line
        known = WAVELENGTH_HEADER.fullmatch(first[1])
        name = expected_header.split(",")[0]
        unit = (known["unit"] or "nm").lower() if known else None
        why = ("a wavelength column, but no later column is one this reader takes"
               if unit == "nm" else
               f"wavelengths in {unit}; this reader takes nm: give them in nm, as {name}"
               if unit else
               f"not a name this reader knows for the first column: name it {name}")
        seen = f" (line {first[0]} begins with {first[1][:40]!r}: {why})"
    return InputError(f"no header row; expected a row '{expected_header}' (comma, tab or "
                      f"semicolon separated) after any preamble{seen}", path)


def _read_rows(path, lines, header, header_line, delimiter, kept, wavelength_first,
               missing=False):
    """The data rows after the header line: `(rows, their line numbers, the first number
    written with a decimal comma or "")`, each row the floats of the `kept` columns. Blank,
    `#` and all-empty rows are skipped; a row with another number of cells is an error.
    With `missing`, an empty cell after the first column reads as NaN."""
    rows, numbers = [], []
    decimal_comma = ""
    for number, raw in enumerate(lines[header_line:], start=header_line + 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        try:
            cells = split_row(line, delimiter)
        except csv.Error as e:
            raise InputError(f"not CSV ({e})", path, number) from None
        if all(c == "" for c in cells):  # a spreadsheet's empty row: ",,,,"
            continue
        if missing and len(cells) < len(header):  # empty last cells, dropped by split_row
            cells += [""] * (len(header) - len(cells))
        if len(cells) != len(header):
            raise _cell_count_error(path, number, line, cells, header, delimiter)
        if delimiter != ",":  # then 18,65 can only be a decimal comma (Excel in Europe)
            found = _decimal_commas(path, number, cells, header, kept, wavelength_first)
            decimal_comma = decimal_comma or found
        rows.append([math.nan if missing and c > 0 and cells[c] == ""
                     else read_number(cells[c], path, number, header[c]) for c in kept])
        numbers.append(number)
    return rows, numbers, decimal_comma


def _cell_count_error(path, number: int, line: str, cells, header, delimiter) -> InputError:
    """The error for data row `line` (file line `number`), whose `cells` are not as many as
    the header's: a row that is not data, an empty last cell, or a count that says why."""
    if not _NUMBER.fullmatch(cells[0]) and not DECIMAL_COMMA.fullmatch(cells[0]):
        shown = line if len(line) <= 40 else line[:37] + "..."
        return InputError(f"a row that is not data ({shown!r}): delete it, or start "
                          "it with '#' to make it a comment (one table a file)",
                          path, number)
    others = [_NAMES[d] for d in DELIMITERS if d != delimiter and d in line]
    hint = (f" (the header is {_NAMES[delimiter]}-separated; this row has "
            f"{' and '.join(others)}s)") if others else ""
    if len(cells) < len(header) and line.endswith(delimiter):
        return InputError("empty cell: expected a number", path, number,
                          header[len(cells)])
    if (not hint and delimiter == "," and len(cells) > len(header)
            and all(c.isdigit() for c in cells)):  # 380,54,81 for 380;54,81
        hint = (" (decimal commas in a comma-separated file? 0,54 is then two cells: "
                "export with ';' or tab between cells, or with decimal points)")
    return InputError(f"{len(cells)} cells where the header has {len(header)}{hint}",
                      path, number)


def _decimal_commas(path, number: int, cells, header, kept, wavelength_first) -> str:
    """Rewrite the `kept` cells of a `;` or tab row written with a decimal comma (`18,65`)
    with a point, in place; returns the first such cell as written, or "". With
    `wavelength_first`, a wavelength such as `1,050` (1050 nm or 1.05?) is an error."""
    found = ""
    for c in kept:
        if (c == 0 and wavelength_first and _THOUSANDS.fullmatch(cells[c])
                and int(cells[c].replace(",", "")) <= 3000):  # 1050 nm or 1.05?
            raise InputError(f"{cells[c]!r} reads as a thousands separator (a "
                             "wavelength over 1000) or a decimal comma: export the "
                             "wavelengths without thousands separators", path,
                             number, header[0])
        if DECIMAL_COMMA.fullmatch(cells[c]):
            found = found or cells[c]
            cells[c] = cells[c].replace(",", ".")
    return found


def read_number(cell: str, path, line: int, column: str) -> float:
    """A cell as a finite float, or an `InputError` saying what was expected."""
    if not _NUMBER.fullmatch(cell):
        shown = cell if len(cell) <= 40 else cell[:37] + "..."
        if DECIMAL_COMMA.fullmatch(cell):
            raise InputError(f"expected a number with a decimal point, got {shown!r} (in a "
                             "comma-separated file a decimal comma cannot be told from a "
                             "column break: export with '.' as the decimal mark, or with "
                             "';' or tabs between columns)", path, line, column)
        if cell.endswith("%") and _NUMBER.fullmatch(cell[:-1].strip()):
            raise InputError(f"expected a number, got {shown!r}: write percent without the "
                             "'%' sign (percent readings are recognised, or pass --percent)",
                             path, line, column)
        if cell.lower().lstrip("+-") in ("nan", "inf", "infinity"):
            raise InputError(f"expected a finite number, got {shown!r}", path, line, column)
        raise InputError(f"expected a number, got {shown!r}", path, line, column)
    value = float(cell)
    if not math.isfinite(value):
        raise InputError(f"expected a finite number, got {cell!r}", path, line, column)
    return value


# Reflectances whose median is above this are read as percent when not told (calibrate,
# fit-skin): no skin or cosmetic reflects more than 1 at most bands, and no percent
# reading of them has a median of 1.5 % (fractions are at most 1).
PERCENT_MEDIAN = 1.5
# Reflectances down to this below 0 are a dark-corrected instrument's noise: read as 0,
# with a note (a black card's reading of -0.0004 should not refuse the whole file).
NEGATIVE_NOISE = 0.005


# A step between readings wider than both of these (nm, and times the file's median step)
# is a hole in the data: the fits bridge it with a straight line (a 110 nm hole across the
# greens can turn a red lipstick orange), so it is named in a warning.
GAP_MIN_NM, GAP_STEPS = 20.0, 3.0


def drop_repeats(data, lines, path, notes: list):
    """`(data, lines)` without rows that repeat the row before them exactly (the same
    wavelength and readings: an export or a merge script's doubled row, which would be
    refused as "must increase"), with a note naming them. A wavelength repeated with other readings
    is left for the caller's check to refuse."""
    data = np.asarray(data)
    equal = (data[1:] == data[:-1]) | (np.isnan(data[1:]) & np.isnan(data[:-1]))  # NaN: missing
    same = np.r_[False, np.all(equal, axis=1)] if len(data) > 1 else np.zeros(len(data), bool)
    if not same.any():
        return data, lines
    lines = list(lines)
    where = [f"{lines[i]} (= {lines[i - 1]})" for i in np.flatnonzero(same)[:5]]
    more = f" and {int(same.sum()) - 5} more" if same.sum() > 5 else ""
    several = same.sum() > 1
    notes.append(f"{path}: line{'s' if several else ''} {', '.join(where)}{more} "
                 f"repeat{'' if several else 's'} the row before: read once")
    keep = ~same
    return data[keep], [n for n, k in zip(lines, keep, strict=True) if k]


def wavelength_gaps(wavelengths, lo: float = 380.0, hi: float = 780.0) -> list[str]:
    """Warnings (one line each) for holes in increasing `wavelengths` that reach into
    [`lo`, `hi`] nm (the render grid, what the fits use): a step wider than `GAP_MIN_NM`
    and `GAP_STEPS` times the median step."""
    wl = np.asarray(wavelengths, np.float64)
    if wl.size < 3:
        return []
    steps = np.diff(wl)
    typical = float(np.median(steps))
    wide = (steps > GAP_MIN_NM) & (steps > GAP_STEPS * typical) & (wl[1:] > lo) & (wl[:-1] < hi)
    return [f"no readings between {wl[i]:g} and {wl[i + 1]:g} nm ({steps[i]:g} nm, where the "
            f"file's step is {typical:g} nm): the fit bridges them with a straight line, so "
            "the colour there is a guess; measure them, or check for rows lost"
            for i in np.flatnonzero(wide)]


def check_percent(values, path) -> None:
    """`InputError` naming `path` when readings given as percent (`--percent`) are all at
    most 1: nothing measured (skin, a film, its background) is below 1 % at every band,
    so they are fractions."""
    values = np.asarray(values)
    if values.size and np.nanmax(values) <= 1.0:
        raise InputError(f"--percent, but every reflectance is at most 1 (median "
                         f"{np.nanmedian(values):.3g}): these are fractions (0-1); leave "
                         "--percent out", path)


def is_wavelength_column(name: str) -> bool:
    """Whether a header cell names the wavelength column (what starts a measurement's table)."""
    return WAVELENGTH_HEADER.fullmatch(name.strip()) is not None


def is_measurement_table(path: Path) -> bool:
    """Whether a file that is not JSON reads as a measurement CSV's table: one of its first
    200 lines is a header row (`read_table`'s rule) whose first cell names the wavelength
    column (`wavelength_nm`, `nm`, ...)."""
    try:
        lines = (line.strip() for line in read_text(path, fallback="cp1252").splitlines()[:200])
        return any(header_row(line, is_wavelength_column) for line in lines
                   if line and not line.startswith("#"))
    except (InputError, csv.Error):  # e.g. a cell over the csv module's field limit
        return False

