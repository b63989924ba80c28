"""File formats: the I/O layer between files and the pure array code.

Everything that reads or writes a data file lives here (or in `io.py`, which holds the error
type, atomic writes and the data folder): CSV tables as instruments export them, JSON
documents, the NIST skin spectra, Lafortune BRDF files and calibrated materials. The optics
modules (`km`, `skin`, `shading`) take and return arrays only.

CSV tables (`read_table`) are read as spectroradiometer software writes them:

- the delimiter is a comma, a tab or a semicolon (the one that splits the header into the
  most cells), fields may be quoted (`"R_inf"`); the text is UTF-8 (a byte-order mark is
  ignored), UTF-16 with a byte-order mark (Windows software's "Unicode") or Windows-1252;
- numbers use a decimal point: `0,45` (a decimal comma) is refused with a one-line error;
- a preamble before the header is skipped: free text, `key: value` or `key,value` lines;
  `# key: value` comments before the header are kept as metadata (`Table.meta`);
- the header is the first row whose first cell names the first column (e.g. `wavelength_nm`)
  and, where the reader asks, that has a cell naming one of the other columns;
- after it, blank lines and `#` lines are skipped; a trailing empty cell (a delimiter at the
  end of every row) is dropped.

Every problem is an `InputError` naming the file, the line and the column.
"""

from __future__ import annotations

import codecs
import contextlib
import csv
import dataclasses
import difflib
import functools
import json
import math
import re
from pathlib import Path

import numpy as np

from .io import InputError, atomic_write, data_dir
from .outputs import slug

__all__ = ["MaterialFile", "Table", "nist_reflectance", "nist_spectrum", "read_json",
           "read_lafortune", "read_material", "read_table", "read_text", "write_json",
           "write_lafortune"]

DELIMITERS = (",", "\t", ";")
MAX_BYTES = 256 * 2**20  # a spectrum at 0.01 nm with 50 columns is ~40 MB
WAVELENGTH_RANGE_NM = (200.0, 3000.0)  # what a spectroradiometer can measure, generously
# S and K of a material file above this (per mm) are refused: cosmetics measure 1e-3 to 1e5, and
# the float32 render of 1e300 (or of 1e37 with its scales at 100) was NaN, a black image (a trial).
MAX_SK_PER_MM = 1e9
# The first column: wavelength_nm (the format's name) or what instrument software and
# spreadsheets write: "Wavelength", "Wavelength (nm)", "Wavelength nm", "wavelength/nm",
# "wavelength [µm]", "lambda", "λ", "wl", "nm", and in German, French, Spanish, Italian,
# Portuguese and Dutch ("Wellenlänge (nm)" was refused as no header; a trial).
WAVELENGTH_HEADER = re.compile(
    r"(?i)(?:wave\s*length|wl|lambda|λ|wellenl(?:ä|ae|a)nge|longueur\s*d['’]?\s*onde"
    r"|longitud\s*de\s*onda|lunghezza\s*d['’]?\s*onda|comprimento\s*de\s*onda|golflengte)"
    r"(?:(?:\s*[_(\[/]\s*|\s+)(?P<unit>nm|um|µm|μm|micron|microns)\s*[)\]]?)?|nm")
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
_DECIMAL_COMMA = re.compile(r"[+-]?\d*,\d+(?:[eE][+-]?\d+)?")
_THOUSANDS = re.compile(r"[1-9]\d{0,2}(?:,\d{3})+")  # 1,050: 1050, or 1.05 (µm)?
_NAMES = {"\t": "tab", ",": "comma", ";": "semicolon"}
# A reading column's header that says its unit is percent: `R_inf (%)`, `Cheek [%]`, `A %`;
# not a number's % (`Foundation 30%`, `Intralipid 2 %`: a name; a review).
PERCENT_UNIT = re.compile(r"\s*[(\[]\s*%\s*[)\]]$|(?<![\d.\s])\s*%$")


def decimal_comma_note(example: str) -> str:
    """The note for a table read with decimal commas, quoting the first of them (a fixed
    "18,65" read as if it quoted the user's data; a trial)."""
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


# Files a table reader is given by mistake, by their first bytes: named in the error
# (they were "a binary file (a NUL byte)" with the line of that byte).
BINARY_KINDS = ((b"\x89PNG\r\n\x1a\n", "a PNG image"), (b"\xff\xd8\xff", "a JPEG image"),
                (b"II*\0", "a TIFF image"), (b"MM\0*", "a TIFF image"),
                (b"GIF8", "a GIF image"), (b"%PDF", "a PDF document"),
                (b"PK\x03\x04", "a ZIP archive (an Excel .xlsx workbook?)"),
                (b"\xd0\xcf\x11\xe0", "an Office document (an Excel .xls workbook?)"))


def read_text(path, fallback: str | None = None, expected: str = "a CSV table (export it "
              "as CSV)") -> str:
    """A text file's contents (UTF-8, or UTF-16 when it starts with UTF-16's byte-order mark;
    the mark dropped); `InputError` if it is not one: missing, unreadable, binary, not UTF-8
    (unless it decodes as the `fallback` encoding, e.g. "cp1252" for Windows exports such as
    the NIST file) or larger than `MAX_BYTES`. A file that starts like an image, a PDF or a
    workbook is named as one (`BINARY_KINDS`), with `expected` saying what was wanted."""
    path = Path(path)
    try:
        size = path.stat().st_size
        if size > MAX_BYTES:
            raise InputError(f"{size / 2**20:.0f} MiB is larger than the {MAX_BYTES >> 20} MiB "
                             "a table may be", path)
        with open(path, "rb") as f:  # bounded: a device or a pipe has no size (/dev/zero
            raw = f.read(MAX_BYTES + 1)  # grew to 24 GB, a trial)
        if len(raw) > MAX_BYTES:
            raise InputError(f"larger than the {MAX_BYTES >> 20} MiB a table may be (a "
                             "device or a pipe?)", path)
    except FileNotFoundError:
        raise InputError("no such file", path) from None
    except IsADirectoryError:
        raise InputError("is a folder, expected a file", path) from None
    except OSError as e:
        raise InputError(f"cannot read ({e.strerror or e.__class__.__name__})", path) from None
    if raw.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        try:
            text = raw.decode("utf-16")  # the mark says which byte order
        except UnicodeDecodeError as e:
            raise InputError(f"not UTF-16 text, though it starts with UTF-16's byte-order mark "
                             f"({e.reason} at byte {e.start})", path) from None
        if "\0" in text:
            raise InputError("a binary file (a NUL character), expected text", path,
                             text[:text.index("\0")].count("\n") + 1)
        return text
    kind = next((k for sig, k in BINARY_KINDS if raw.startswith(sig)), None)
    if kind is not None:  # a file of a kind users pick by mistake: say which
        raise InputError(f"{kind}, not text: expected {expected}", path)
    if b"\0" in raw:
        text = _utf16_without_mark(raw)
        if text is not None:  # Windows "Unicode" saved without the mark (a trial)
            return text
        line = raw[:raw.index(b"\0")].count(b"\n") + 1
        raise InputError("a binary file (a NUL byte), expected UTF-8 text", path, line)
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        if fallback is not None:
            with contextlib.suppress(UnicodeDecodeError):
                return raw.decode(fallback)
        line = raw[:e.start].count(b"\n") + 1
        nor = "" if fallback is None else f" nor {fallback}"
        raise InputError(f"not UTF-8{nor} text (byte 0x{raw[e.start]:02x})", path,
                         line) from None


def _utf16_without_mark(raw: bytes) -> str | None:
    """`raw` decoded as UTF-16 when it has no byte-order mark but is plainly UTF-16 text:
    an even length, every other byte NUL in its first 2 KiB (Latin text: the high bytes)
    and none of the others, and it decodes with no NUL character; else None."""
    head = raw[:2048]
    if len(raw) % 2 or len(head) < 4:
        return None
    for order, zeros, rest in (("utf-16-le", head[1::2], head[0::2]),
                               ("utf-16-be", head[0::2], head[1::2])):
        if zeros.count(0) >= 0.9 * len(zeros) and rest.count(0) == 0:
            try:
                text = raw.decode(order)
            except UnicodeDecodeError:
                return None
            return None if "\0" in text else text
    return None


def _split(line: str, delimiter: str) -> list[str]:
    cells = next(csv.reader([line], delimiter=delimiter, skipinitialspace=True), [])
    cells = [c.strip() for c in cells]
    while len(cells) > 1 and cells[-1] == "":
        cells.pop()
    return cells


def text_rows(path):
    """`(line number, cells)` of each row of a text table that is not blank or a comment,
    split at whichever delimiter gives the most cells; nothing for a file that cannot be
    read as text, and no more rows from the first that is not CSV. For messages that
    guess what a file that failed to read was meant to be."""
    try:
        lines = read_text(path, fallback="cp1252").splitlines()
    except InputError:
        return
    for number, raw in enumerate(lines, start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        try:
            yield number, max((_split(line, d) for d in DELIMITERS), key=len)
        except csv.Error:
            return


def _header_row(line: str, first_column, other_column=None):
    """`(cells, delimiter)` if `line` is a table's header row (its first cell accepted by
    `first_column` and, with `other_column`, a later cell by that), else None; of several
    delimiters that fit, the one that gives the most cells. Raises `csv.Error`."""
    split = {d: _split(line, d) for d in DELIMITERS}
    found = [d for d in DELIMITERS if first_column(split[d][0]) and (
        other_column is None or any(other_column(c) for c in split[d][1:]))]
    if not found:
        return None
    delimiter = max(found, key=lambda d: len(split[d]))
    return split[delimiter], delimiter


def read_table(path, first_column, expected_header: str, min_rows: int = 1,
               other_column=None, once: tuple[str, ...] = (), on_header=None,
               wavelength_first: bool = False) -> Table:
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

    **Returns:** a `Table`. **Raises:** `InputError` on anything malformed.
    """
    path = Path(path)
    # Instruments' Windows software writes Windows-1252 (µm, °, curly quotes in the header
    # and comments); a table's numbers read the same either way.
    text = read_text(path, fallback="cp1252")
    lines = text.splitlines()
    meta: dict[str, tuple[str, int]] = {}
    header = delimiter = None
    header_line = 0
    first = None  # the last line before the data whose first cell is text: the header meant
    data_seen = False
    try:
        for number, raw in enumerate(lines, start=1):
            line = raw.strip()
            if not line:
                continue
            if not data_seen and not line.startswith("#"):
                cell = re.split(r"[,;\t]", line, maxsplit=1)[0].strip().strip('"')
                if _NUMBER.fullmatch(cell) or _DECIMAL_COMMA.fullmatch(cell):
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
            row = _header_row(line, first_column, other_column)
            if row is not None:
                (header, delimiter), header_line = row, number
                break
    except csv.Error as e:
        raise InputError(f"not CSV ({e})", path, number) from None
    if header is None:
        seen = ""
        if first is not None:  # the row above the data (a preamble line was quoted; a review)
            known = WAVELENGTH_HEADER.fullmatch(first[1])
            name = expected_header.split(",")[0]
            unit = (known["unit"] or "nm").lower() if known else None
            why = ("a wavelength column, but no later column is one this reader takes"
                   if unit == "nm" else
                   f"wavelengths in {unit}; this reader takes nm: give them in nm, as {name}"
                   if unit else
                   f"not a name this reader knows for the first column: name it {name}")
            seen = f" (line {first[0]} begins with {first[1][:40]!r}: {why})"
        raise InputError(f"no header row; expected a row '{expected_header}' (comma, tab or "
                         f"semicolon separated) after any preamble{seen}", path)
    for i, name in enumerate(header):
        if name == "":
            raise InputError(f"header cell {i + 1} is empty", path, header_line)
        if name in header[:i]:
            raise InputError("column appears twice", path, header_line, name)
    skipped = set(on_header(header, meta, header_line)) if on_header is not None else set()
    kept = [c for c, name in enumerate(header) if name not in skipped]

    rows, numbers = [], []
    decimal_comma = ""
    for number, raw in enumerate(lines[header_line:], start=header_line + 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        try:
            cells = _split(line, delimiter)
        except csv.Error as e:
            raise InputError(f"not CSV ({e})", path, number) from None
        if all(c == "" for c in cells):  # a spreadsheet's empty row: ",,,,"
            continue
        if len(cells) != len(header):
            if not _NUMBER.fullmatch(cells[0]) and not _DECIMAL_COMMA.fullmatch(cells[0]):
                shown = line if len(line) <= 40 else line[:37] + "..."
                raise InputError(f"a row that is not data ({shown!r}): delete it, or start "
                                 "it with '#' to make it a comment (one table a file)",
                                 path, number)
            others = [_NAMES[d] for d in DELIMITERS if d != delimiter and d in line]
            hint = (f" (the header is {_NAMES[delimiter]}-separated; this row has "
                    f"{' and '.join(others)}s)") if others else ""
            if len(cells) < len(header) and line.endswith(delimiter):
                raise InputError("empty cell: expected a number", path, number,
                                 header[len(cells)])
            if (not hint and delimiter == "," and len(cells) > len(header)
                    and all(c.isdigit() for c in cells)):  # 380,54,81 for 380;54,81 (a trial)
                hint = (" (decimal commas in a comma-separated file? 0,54 is then two cells: "
                        "export with ';' or tab between cells, or with decimal points)")
            raise InputError(f"{len(cells)} cells where the header has {len(header)}{hint}",
                             path, number)
        if delimiter != ",":  # then 18,65 can only be a decimal comma (Excel in Europe)
            for c in kept:
                if (c == 0 and wavelength_first and _THOUSANDS.fullmatch(cells[c])
                        and int(cells[c].replace(",", "")) <= 3000):  # 1050 nm or 1.05?
                    raise InputError(f"{cells[c]!r} reads as a thousands separator (a "
                                     "wavelength over 1000) or a decimal comma: export the "
                                     "wavelengths without thousands separators", path,
                                     number, header[0])
                if _DECIMAL_COMMA.fullmatch(cells[c]):
                    decimal_comma = decimal_comma or cells[c]
                    cells[c] = cells[c].replace(",", ".")
        rows.append([_number(cells[c], path, number, header[c]) for c in kept])
        numbers.append(number)
    if len(rows) < min_rows:
        rows_ = "row" if min_rows == 1 else "rows"
        raise InputError(f"needs at least {min_rows} data {rows_}, found {len(rows)}", path,
                         header_line)
    header = [header[c] for c in kept]
    data = np.asarray(rows, np.float64).reshape(len(rows), len(header))
    return Table(path, header, header_line, data, numbers, meta, delimiter, decimal_comma)


def _number(cell: str, path, line: int, column: str) -> float:
    """A cell as a finite float, or an `InputError` saying what was expected."""
    if not _NUMBER.fullmatch(cell):
        shown = cell if len(cell) <= 40 else cell[:37] + "..."
        if _DECIMAL_COMMA.fullmatch(cell):
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


# ---------------------------------------------------------------- JSON


# Reflectances whose median is above this are read as percent when not told (calibrate,
# fit-skin): no skin or cosmetic reflects more than 1 at most bands, and no percent
# reading of them has a median of 1.5 % (fractions are at most 1).
PERCENT_MEDIAN = 1.5
# Reflectances down to this below 0 are a dark-corrected instrument's noise: read as 0,
# with a note (a black card's reading of -0.0004 refused the whole file; a trial).
NEGATIVE_NOISE = 0.005


# A step between readings wider than both of these (nm, and times the file's median step)
# is a hole in the data: the fits bridge it with a straight line (a 110 nm hole across the
# greens turned a red lipstick orange with no word; a trial).
GAP_MIN_NM, GAP_STEPS = 20.0, 3.0


def drop_repeats(data, lines, path, notes: list):
    """`(data, lines)` without rows that repeat the row before them exactly (the same
    wavelength and readings: an export or a merge script's doubled row, refused as "must
    increase"; a trial), with a note naming them. A wavelength repeated with other readings
    is left for the caller's check to refuse."""
    data = np.asarray(data)
    same = np.r_[False, np.all(data[1:] == data[:-1], axis=1)] if len(data) > 1 else \
        np.zeros(len(data), bool)
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
    if values.size and np.max(values) <= 1.0:
        raise InputError(f"--percent, but every reflectance is at most 1 (median "
                         f"{np.median(values):.3g}): these are fractions (0-1); leave "
                         "--percent out", path)


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

    from .shading import lafortune

    return lafortune.from_json(read_json(path, "BRDF file"), Path(path),
                               jnp.float32 if dtype is None else dtype)


def write_lafortune(p, path, **extra) -> None:
    """Write Lafortune lobes `p` (and `extra` keys, e.g. fit statistics) as a material file."""
    from .shading import lafortune

    write_json(lafortune.to_json(p, **extra), path)


# ---------------------------------------------------------------- the NIST skin spectra

NIST_FILE = "nist_skin_reflectance_M38597.csv"
NIST_SUBJECTS = 100


@functools.cache
def _nist_table() -> tuple[np.ndarray, np.ndarray]:
    """Wavelengths (m,) and the subjects' mean reflectances (100, m), from the shipped CSV
    (four columns per subject: three readings and their mean)."""
    path = data_dir() / "spectra" / NIST_FILE
    wl, means = [], []
    for line in path.read_text(encoding="latin-1").splitlines():
        cells = line.split(",")
        if cells and cells[0].strip().isdigit():
            wl.append(float(cells[0]))
            means.append([float(cells[1 + 4 * s + 3]) for s in range(NIST_SUBJECTS)])
    return np.asarray(wl), np.asarray(means).T


def nist_spectrum(subject: int) -> tuple[np.ndarray, np.ndarray]:
    """NIST subject `subject` (1–100)'s mean forearm reflectance as measured:
    `(wavelengths nm, R)` (Cooksey, Allen, Tsai 2017; see `skin`)."""
    if not 1 <= subject <= NIST_SUBJECTS:
        raise InputError(f"NIST skin subject must be 1–{NIST_SUBJECTS}, got {subject}",
                         key="skin.subject")
    wl, means = _nist_table()
    return wl, means[subject - 1]


def nist_reflectance(subject: int, grid) -> np.ndarray:
    """Subject `subject`'s mean reflectance on `grid` (a `spectral.Grid`; host float64)."""
    return np.interp(grid.wavelengths, *nist_spectrum(subject))


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


def _is_measurement_table(path: Path) -> bool:
    """Whether a file that is not JSON reads as a measurement CSV's table: one of its first
    200 lines is a header row (`read_table`'s rule) whose first cell names the wavelength
    column (`wavelength_nm`, `nm`, ...)."""
    from jaxskin.fitting.measurements import is_wavelength_column

    try:
        lines = (line.strip() for line in read_text(path, fallback="cp1252").splitlines()[:200])
        return any(_header_row(line, is_wavelength_column) for line in lines
                   if line and not line.startswith("#"))
    except (InputError, csv.Error):  # e.g. a cell over the csv module's field limit
        return False


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
        if _is_measurement_table(path):  # a measurement saved as .txt, .dat, ...
            raise InputError("a measurement table (a wavelength column), expected a material "
                             f"JSON: {_calibrate_first(path)}", path) from None
        raise
    if not isinstance(doc, dict):
        raise InputError("expected a JSON object (a material written by jaxskin calibrate)",
                         path)
    model = doc.get("model", "kubelka-munk")
    if model == "lafortune" or "lobes" in doc:  # a fit-brdf output (a trial)
        raise InputError("a Lafortune BRDF (written by jaxskin fit-brdf; it goes in "
                         "material.brdf), expected a Kubelka-Munk material (written by jaxskin "
                         "calibrate)", path, key="model" if "model" in doc else None)
    if model != "kubelka-munk":  # it was not read at all
        raise InputError(f"expected \"kubelka-munk\" (or no model key), got {model!r}", path,
                         key="model")
    arrays = {}
    known = ("wavelength_nm", "S_per_mm", "K_per_mm")
    for k in known:
        if k not in doc:  # a hand edit renamed it (S_per_mn): name both (a trial)
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


# ---------------------------------------------------------------- haemoglobin, spectra to fit

HAEMOGLOBIN_FILE = "hemoglobin_prahl.csv"


@functools.cache
def haemoglobin_table() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Prahl's molar extinction of oxy- and deoxy-haemoglobin (OMLC; the shipped
    `data/spectra/hemoglobin_prahl.csv`): `(wavelengths nm, e_HbO2, e_Hb)` in cm⁻¹/M."""
    t = read_table(data_dir() / "spectra" / HAEMOGLOBIN_FILE, lambda c: c == "wavelength_nm",
                   "wavelength_nm,e_HbO2,e_Hb")
    return t.column("wavelength_nm"), t.column("e_HbO2"), t.column("e_Hb")


def _nm_column(cell: str) -> bool:
    """Whether a header cell names a wavelength column in nm (`WAVELENGTH_HEADER` with nm
    or no unit: fit-skin's spectra are in nm)."""
    m = WAVELENGTH_HEADER.fullmatch(cell.strip())
    return m is not None and (m["unit"] or "nm").lower() == "nm"


def read_spectra(path, percent: bool | None = False, notes: list | None = None
                 ) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Reflectance spectra to fit, one per column: `(names, wavelengths (n,), R (m, n))`.

    Two layouts: a wide CSV (`wavelength_nm` — or `Wavelength (nm)` — then one column per
    spectrum, named by its header), and the NIST skin file's (`Wavelength (nm)` then groups
    `R1, R2, R3, Average` under a row naming `Subject k`: each subject's `Average` is read,
    named `subject_k`). Reflectance in 0–1 (`percent`: 0–100; `None`: percent when the
    median is above `PERCENT_MEDIAN`, as `calibrate` guesses, with a line appended to
    `notes`); wavelengths increasing, or all decreasing (then reversed, with a note).
    `InputError` names the file, line and column of anything else.
    """
    path = Path(path)
    text = read_text(path, fallback="cp1252")
    lines = text.splitlines()
    header_at = None
    for i, raw in enumerate(lines):
        cells = _split(raw.strip(), ",") if raw.strip() and not raw.startswith("#") else []
        if cells and _nm_column(cells[0]):
            header_at = i
            break
    t = None
    if header_at is not None and "Average" in _split(lines[header_at], ","):
        header = _split(lines[header_at], ",")
        above = next((_split(lines[j], ",") for j in range(header_at - 1, -1, -1)
                      if lines[j].strip().strip(",")), [])
        columns, names = [], []
        for c, name in enumerate(header):
            if name == "Average":
                label = next((above[j] for j in range(min(c, len(above) - 1), 0, -1)
                              if j < len(above) and above[j]), f"column {c + 1}")
                names.append(slug(label.strip().lower().replace(" ", "_")))
                columns.append(c)
        rows, wl = [], []
        for number, raw in enumerate(lines[header_at + 1:], start=header_at + 2):
            cells = _split(raw.strip(), ",")
            if not raw.strip() or raw.startswith("#"):
                continue
            if len(cells) < len(header):
                raise InputError(f"{len(cells)} cells where the header has {len(header)}",
                                 path, number)
            wl.append(_number(cells[0], path, number, header[0]))
            rows.append([_number(cells[c], path, number, f"{names[k]} Average")
                         for k, c in enumerate(columns)])
        if len(wl) < 2:
            raise InputError("needs at least 2 rows of spectra", path, header_at + 1)
        wavelengths, R = np.asarray(wl), np.asarray(rows).T
        header_line, line_of, wl_name = header_at + 1, None, header[0]
    else:
        t = read_table(path, _nm_column,
                       "wavelength_nm,<spectrum name>,...", min_rows=2, wavelength_first=True)
        if len(t.header) < 2:
            raise t.error("no spectra: expected wavelength_nm and one column per spectrum")
        notes = [] if notes is None else notes
        data, line_of = drop_repeats(t.data, t.lines, path, notes)
        names, wavelengths, R = t.header[1:], data[:, 0], data[:, 1:].T
        header_line, wl_name = t.header_line, t.header[0]
    notes = [] if notes is None else notes
    if t is not None and t.decimal_comma:
        notes.append(f"{path}: {decimal_comma_note(t.decimal_comma)}")
    if len(wavelengths) > 1 and np.all(np.diff(wavelengths) < 0):  # long ones first
        wavelengths, R = wavelengths[::-1], R[:, ::-1]
        line_of = None if line_of is None else list(line_of)[::-1]
        notes.append(f"{path}: wavelengths descend: read in increasing order")
    if np.any(np.diff(wavelengths) <= 0):
        row = int(np.flatnonzero(np.diff(wavelengths) <= 0)[0]) + 1
        raise InputError("wavelengths must increase (or all decrease)", path,
                         None if line_of is None else line_of[row], wl_name)
    # A header that says % (`Forearm A (%)`): that spectrum in percent, named without it,
    # as calibrate reads its columns (the unit stayed in the names; a trial).
    columns = list(names)  # as the file spells them, for the messages
    marked = np.array([bool(PERCENT_UNIT.search(n)) for n in names])
    names = [PERCENT_UNIT.sub("", n) if m else n for n, m in zip(names, marked, strict=True)]
    for k in np.flatnonzero(marked):
        if not names[k]:
            raise InputError("a spectrum's name is its unit alone: name the column", path,
                             header_line, columns[k])
        if np.max(R[k]) <= 1.0:  # no skin reflects under 1 % at every band
            raise InputError(f"says %, but every reading is at most 1 (median "
                             f"{np.median(R[k]):.3g}): these are fractions (0-1); remove the % "
                             "from the header", path, header_line, columns[k])
    if marked.any():
        said = [c for c, m in zip(columns, marked, strict=True) if m]
        these = "', '".join(said[:3])
        notes.append(f"{path}: column{'s' if len(said) > 1 else ''} '{these}'"
                     f"{' ...' if len(said) > 3 else ''} say{'' if len(said) > 1 else 's'} %: "
                     "read as percent (/ 100)")
    rest = R[~marked]
    if percent is None:
        percent = bool(rest.size) and float(np.median(rest)) > PERCENT_MEDIAN
        if percent:
            notes.append(f"{path}: reflectances have a median of {np.median(rest):.3g}: read "
                         "as percent (/ 100; --percent says so)")
    elif percent and rest.size:
        check_percent(rest, path)
    tops = np.where(marked | bool(percent), 100.0, 1.0)
    R = R / tops[:, None]
    noise = (R < 0) & (R >= -NEGATIVE_NOISE)  # as calibrate reads them (it refused -0.001)
    for k in np.flatnonzero(noise.any(axis=1)):
        notes.append(f"{path}: spectrum '{names[k]}': {int(noise[k].sum())} reading"
                     f"{'s' if noise[k].sum() > 1 else ''} below 0 (down to "
                     f"{R[k][noise[k]].min() * tops[k]:g}, within the "
                     f"{NEGATIVE_NOISE * tops[k]:g} of noise) read as 0")
    R = np.where(noise, 0.0, R)
    for k, name in enumerate(columns):
        bad = np.flatnonzero((R[k] < 0) | (R[k] > 1.0))
        if bad.size:
            top = tops[k]
            raise InputError(f"reflectance must be in [0, {top:g}]"
                             + (f" (below the -{NEGATIVE_NOISE * top:g} read as noise: "
                                "reflectances cannot be negative)"
                                if R[k, bad[0]] < 0 else
                                "" if top == 100 else " (use --percent for 0-100)")
                             + f", got {R[k, bad[0]] * top:g} at {wavelengths[bad[0]]:g} nm",
                             path, None if line_of is None else line_of[bad[0]], name)
    seen = set()
    for name in names:
        if name in seen:
            raise InputError("two spectra have this name", path, header_line, name)
        seen.add(name)
    return list(names), wavelengths, R
