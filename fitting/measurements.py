"""Spectroradiometer measurement CSVs for Kubelka–Munk calibration (Huang et al. 2013 §4).

The format (also in the documentation, docs/reference/formats.md):

    # name: foundation_1          (optional; default: the file's stem, made safe)
    # thickness_mm: 0.15          (optional; the thickness of a bare `R` column)
    wavelength_nm,R_0.05mm,R_0.15mm,R_inf,R_g
    380,0.0712,0.1134,0.2051,0.0398
    ...

- `R_<X>mm`: reflectance of a thin layer X mm thick over the background (one or more).
- `R`: a thin layer whose thickness comes from `--thickness` or `# thickness_mm:`.
- `R_inf`: an opaque layer. `R_g`: the background alone (black or white card).
- Reflectance factors in [0, 1] (or 0–100 with `percent=True`).
- Raw radiance instead: the same columns with `E_` in place of `R_` (`E_0.15mm`, `E_inf`,
  `E_g`; `E_R_0.15mm` is accepted too) plus `E_white`, the barium sulfate standard; then
  R = E / E_white (eq. 8).

The header is the first row whose first cell names the wavelength (`wavelength_nm`, `nm`,
`Wavelength (nm)`, ...) and that has a column starting with `R` or `E`.

Anything else is an `InputError` naming the file, the line and the column.
"""

from __future__ import annotations

import dataclasses
import fnmatch
import math
import re
from pathlib import Path

import numpy as np

from jaxskin.formats import (
    DECIMAL_COMMA,
    NEGATIVE_NOISE,
    PERCENT_MEDIAN,
    PERCENT_UNIT,
    WAVELENGTH_HEADER,
    WAVELENGTH_RANGE_NM,
    check_percent,
    decimal_comma_note,
    drop_repeats,
    is_wavelength_column,
    read_table,
)
from jaxskin.io import InputError
from jaxskin.outputs import MAX_NAME

__all__ = ["Measurement", "is_wavelength_column", "read_measurement"]

# A thin layer's column, after `_canonical`: R_0.05mm, R_0.05_mm (from "R 0.05 mm"),
# R0.05mm, R_50um, R_50µm; E_… for radiance.
THIN_COLUMN = re.compile(r"^(?:R|E)_?(?P<x>.+?)_?(?P<unit>mm|um|µm|μm)$")
_NAME = re.compile(r"[\w.+-]+")  # a material name (it names the output files)
MAX_THICKNESS_MM = 100.0  # a cosmetic layer is µm to a few mm; beyond this it is a typo
# Thin-layer thicknesses outside this are named in a note: cosmetic films are µm to a
# tenth of a mm; R_3mm for R_3um fits as well with S, K 1000× too small.
USUAL_THICKNESS_MM = (1e-4, 1.0)
MAX_RADIANCE = 1e30  # any unit of radiance or counts; beyond this it is an overflow


def _is_reading(name: str) -> bool:
    """Whether a header cell may name a reading: reflectance `R…` or radiance `E…`."""
    return name.startswith(("R", "E"))


@dataclasses.dataclass(frozen=True)
class Measurement:
    """One cosmetic's reflectance measurements, all on one wavelength grid.

    **Fields:** `path`, `name`, `wavelength_nm (n,)`, `thickness_mm (m,)`, `R (m, n)` of the
    thin layers over the background, `R_inf (n,)`, `R_g (n,)`, `columns`: the CSV column
    each thin layer came from, `header_line`: the header's line number in the file, `notes`:
    what the reader inferred (µm wavelengths, percent reflectance), one line each.
    """

    path: Path
    name: str
    wavelength_nm: np.ndarray
    thickness_mm: np.ndarray
    R: np.ndarray
    R_inf: np.ndarray
    R_g: np.ndarray
    columns: tuple[str, ...]
    header_line: int
    notes: tuple[str, ...] = ()


def read_measurement(path, thickness_mm: float | None = None, percent: bool = False,
                     ignore=(), white_reflectance: float | None = None):
    """Read and check one measurement CSV.

    **Arguments:**

    - `path`: the CSV file.
    - `thickness_mm`: thickness for a bare `R` column; overrides `# thickness_mm:`.
    - `percent`: reflectance columns are 0–100 instead of 0–1 (radiance columns unaffected).
      Without it, reflectances whose median is above 1.5 are read as percent (and must then
      lie in [0, 100]), with a note; otherwise anything above 1 is an error.
    - `white_reflectance`: the white standard's reflectance in (0, 1] (a certified tile's
      0.98): radiance columns give R = E / E_white × this; overrides the file's
      `# white_reflectance:` line; default 1 (Huang et al.'s barium sulfate).
    - `ignore`: column names or `fnmatch` patterns (`SD_*`) of columns to skip, as the
      file's own `# ignore: NAME, NAME` line does; a name in that line that is no column
      is an error, a pattern here that matches nothing in this file is not.

    Wavelengths all under 10 are read as µm (× 1000, with a note); after that they must lie
    in 200–3000 nm and increase.

    **Returns:** a `Measurement`. **Raises:** `InputError` on anything malformed.
    """
    path = Path(path)
    ignore = (ignore,) if isinstance(ignore, str) else tuple(ignore)
    if thickness_mm is not None and not (
            math.isfinite(thickness_mm) and 0 < thickness_mm <= MAX_THICKNESS_MM):
        raise InputError(f"--thickness must be a positive number of mm (at most "
                         f"{MAX_THICKNESS_MM:g}), got {thickness_mm}", path)
    seen = {}

    def on_header(header, meta, line):
        """The columns to skip; the others classified before any row is read (so that an
        unknown text column is named as unknown, not as a cell that is no number)."""
        seen.update(_header_columns(path, header, meta, line, ignore, thickness_mm))
        return seen["ignored"]

    table = _read_table(path, on_header)
    meta, header, header_line = table.meta, table.header, table.header_line
    comment_thickness, columns, ignored = seen["comment"], seen["columns"], seen["ignored"]
    repeats = []
    data, numbers = drop_repeats(table.data, table.lines, path, repeats)
    descending = len(data) > 1 and bool(np.all(np.diff(data[:, 0]) < 0))
    if descending:  # some instruments export the long wavelengths first
        data, numbers = data[::-1], list(numbers)[::-1]

    wl, notes = _wavelengths_nm(data[:, 0], header[0], path, numbers)
    notes += repeats
    if table.decimal_comma:
        notes.append(f"{path}: {decimal_comma_note(table.decimal_comma)}")
    if ignored:
        notes.append(f"{path}: ignored column{'s' if len(ignored) > 1 else ''} "
                     + ", ".join(ignored))
    if descending:
        notes.append(f"{path}: wavelengths descend: read in increasing order")
    notes += _thickness_notes(path, columns, meta, thickness_mm, comment_thickness)
    white = _white_reflectance(path, meta, columns, white_reflectance, notes)
    said = [n for n in columns if PERCENT_UNIT.search(n) and not _is_radiance(n)]
    if said and not percent:  # the header says so: not left to the median's guess
        these = "', '".join(said)
        notes.append(f"{path}: column{'s' if len(said) > 1 else ''} '{these}' say"
                     f"{'' if len(said) > 1 else 's'} %: read as percent (/ 100)")
    reflectance = _reflectances(data, header, columns, path, numbers, percent, notes, white,
                                marked=said)
    thin = sorted((x, name) for name, (kind, x) in columns.items() if kind == "thin")
    R = np.stack([reflectance[name] for _, name in thin])
    R_inf, R_g = reflectance["inf"], reflectance["g"]
    if np.all(np.abs(R_g - R_inf) <= 1e-12):
        raise InputError(
            "R_g equals R_inf at every wavelength: the background must differ from the opaque "
            "layer (a black or white card)", path, header_line, _column_of(columns, "g"),
        )
    name = _material_name(path, meta, notes)
    return Measurement(
        path=path, name=name, wavelength_nm=wl, thickness_mm=np.array([x for x, _ in thin]),
        R=R, R_inf=R_inf, R_g=R_g, columns=tuple(n for _, n in thin), header_line=header_line,
        notes=tuple(notes),
    )


def _header_columns(path, header, meta, line, ignore, thickness_mm):
    """`{"ignored": the columns to skip, "comment": the `# thickness_mm:` line's thickness
    or None, "columns": the others classified (`_classify`)}`, from the header row and the
    `# key:` lines before it; `ignore` and `thickness_mm` as `read_measurement` takes them."""
    names = [n for n in header[1:] if any(fnmatch.fnmatchcase(n, p) for p in ignore)]
    if header[0] in ignore:  # named outright (not by a pattern): refused, not passed over
        raise InputError("--ignore names the first column, the wavelengths, which cannot "
                         "be ignored", path, line, header[0])
    if "ignore" in meta:
        value, number = meta["ignore"]
        for name in filter(None, (n.strip() for n in re.split(r"[,;]", value))):
            found = [n for n in header if fnmatch.fnmatchcase(n, name)]
            if not found:
                raise InputError(f"'# ignore:' names {name!r}, which is no column of the "
                                 "header", path, number)
            names += found
    ignored = list(dict.fromkeys(names))
    if header[0] in ignored:
        raise InputError("the first column cannot be ignored", path, line, header[0])
    comment = None
    if "thickness_mm" in meta:
        value, number = meta["thickness_mm"]
        comment = _positive(value, path, number, key="thickness_mm")
    bare = thickness_mm if thickness_mm is not None else comment
    columns = _classify([n for n in header if n not in ignored], path, line, bare)
    return {"comment": comment, "columns": columns, "ignored": ignored}


def _read_table(path, on_header):
    """The measurement's table (`read_table` with this format's header and `# key:` lines);
    a file with no header row that is laid out in another way is named as such
    (`_other_layout`)."""
    try:
        return read_table(path, is_wavelength_column, "wavelength_nm,R_<X>mm,...,R_inf,R_g",
                          min_rows=2, other_column=_is_reading,
                          once=("name", "thickness_mm", "ignore", "white_reflectance"),
                          on_header=on_header, wavelength_first=True)
    except InputError as e:
        if "no header row" in str(e) and (layout := _other_layout(path)) is not None:
            raise InputError(layout[1], path, layout[0]) from None
        raise


def _thickness_notes(path, columns, meta, thickness_mm, comment_thickness) -> list[str]:
    """Notes on the thicknesses: a thin layer outside `USUAL_THICKNESS_MM` (a unit mistaken?),
    and a `# thickness_mm:` line that is not used or that `--thickness` overrides."""
    notes = []
    lo, hi = USUAL_THICKNESS_MM
    for name, (kind, x) in columns.items():
        if kind == "thin" and not lo <= x <= hi:
            notes.append(f"{path}: column '{name}': a {x:g} mm film; cosmetic films are "
                         f"{lo * 1000:g} µm to {hi:g} mm thick, and S, K scale as 1 / "
                         f"thickness: {'µm (R_<X>um)' if x > hi else 'mm'} meant?")
    if comment_thickness is not None:  # said, so not dropped in silence
        value, number = meta["thickness_mm"]
        said = f"{path}:{number}: '# thickness_mm: {value}'"
        if not {"R", "E"} & set(columns):
            notes.append(f"{said} is not used: no bare R (or E) column; the R_<X>mm columns "
                         "name their own thicknesses")
        elif thickness_mm is not None and thickness_mm != comment_thickness:
            notes.append(f"{said} is overridden by --thickness {thickness_mm:g}")
    return notes


def _white_reflectance(path, meta, columns, white_reflectance, notes) -> float:
    """The white standard's reflectance: `--white-reflectance`, else the file's
    `# white_reflectance:` line (read only with radiance columns), else 1; a note when one
    is given but not used, or overridden."""
    white = 1.0
    radiance = "white" in {kind for kind, _ in columns.values()}
    if "white_reflectance" in meta and radiance:
        value, number = meta["white_reflectance"]
        white = _fraction(value, path, number, "white_reflectance")
        if white_reflectance is not None and white_reflectance != white:
            notes.append(f"{path}:{number}: '# white_reflectance: {value}' is overridden by "
                         f"--white-reflectance {white_reflectance:g}")
    if white_reflectance is not None:
        white = white_reflectance
    if not radiance and (white != 1.0 or "white_reflectance" in meta):
        notes.append(f"{path}: the white standard's reflectance is not used: no radiance "
                     "columns (E_... with E_white)")
    return white


def _material_name(path, meta, notes) -> str:
    """The material's name: the file's `# name:` line, checked, or its stem
    (`_name_from_stem`)."""
    name, line = meta.get("name", ("", 0))
    if not name:
        return _name_from_stem(path, notes)
    if not _NAME.fullmatch(name):
        safe = _safe_name(name)
        hint = f", e.g. '# name: {safe}'" if safe else ""
        raise InputError(
            f"name {name!r} must be letters, digits, '.', '_', '+' or '-' (it names "
            f"files){hint}", path, line,
        )
    return name


_WAVELENGTH_CELL = re.compile(r"(?i)\d+(?:\.\d+)?\s*(?:nm)?")


# A reading's column written in lower case (r_0.05mm, r_inf, e_white), for `_other_layout`.
_LOWER_READING = re.compile(r"r_[\d.]+\s*(mm|um|µm)|r_?inf|r_?g|e_\S+")


def _other_layout(path):
    """`(line, message)` when a table with no header row is laid out in a way the format
    is not: wavelengths along a row (one row per sample, as some instruments export), or
    the wavelength column after another (a sample name first); else None."""
    from jaxskin.formats import read_text, text_rows

    # (read as text already: this runs after `read_table` found no header row in it)
    if (Path(path).suffix.lower() == ".json"
            or read_text(path, fallback="cp1252").lstrip().startswith("{")):
        return None, ("a JSON file, not a measurement CSV: a calibrated material (what "
                      "calibrate writes) is named by a scene's [[layer]] material; calibrate "
                      "reads wavelength_nm,R_<X>mm,... tables")
    for number, cells in text_rows(path):
        if (len(cells) >= 2 and is_wavelength_column(cells[0])
                and not any(_is_reading(c) for c in cells[1:])):
            shown = ", ".join(repr(c) for c in cells[1:3]) + (", ..." if len(cells) > 3 else "")
            reads = "calibrate reads R_<X>mm, R_inf, R_g or E_... columns"
            if any(_LOWER_READING.fullmatch(c) for c in cells[1:]):  # r_0.05mm: the case
                return number, (f"no column is a cosmetic's reading ({shown}): {reads}, "
                                "with a capital R or E")
            return number, (f"no column is a cosmetic's reading ({shown}; {reads}): skin "
                            "reflectance spectra, one per column, are fitted with "
                            f"'jaxskin fit-skin {path}'")
        if {"theta_in_deg", "wi_x"} & set(cells):
            return number, ("BRDF samples (angles and R, G, B), not a measurement of "
                            "spectra: fit them with 'jaxskin fit-brdf'")
        along = [c for c in cells[1:] if _WAVELENGTH_CELL.fullmatch(c)
                 and 200 <= float(c.lower().removesuffix("nm")) <= 3000]
        if len(cells) >= 5 and len(along) >= 0.8 * (len(cells) - 1):
            return number, (f"wavelengths run along this row ({cells[1]}, {cells[2]}, ...: "
                            "one row per reading): the format has them down the first "
                            "column, one column per reading; transpose the table (in a "
                            "spreadsheet: copy, then paste special > transpose)")
        later = [c for c in cells[1:] if is_wavelength_column(c)]
        if later and any(_is_reading(c) for c in cells):
            before = cells[:cells.index(later[0])]
            return number, (f"the wavelength column '{later[0]}' is not the first: move it "
                            f"first, or delete the column{'s' if len(before) > 1 else ''} "
                            f"before it ({', '.join(repr(c) for c in before)})")
    return None


def _safe_name(text: str) -> str:
    """`text` as a material name: lowercase, each run of characters other than letters,
    digits, `.`, `+`, `-` one `_`, none of `_.+-` at the ends (may be empty)."""
    return re.sub(r"[^\w.+-]+", "_", text.lower()).strip("_.+-")


def _name_from_stem(path, notes) -> str:
    """The file's stem as the material name; one that the name rule refuses
    (`Lipstick Red (batch 5)`) is made safe: lowercase, runs of characters other than
    letters (any script's), digits, `.`, `+`, `-` as `_`, no `_`, `.`, `+`, `-` at the ends
    (`lipstick_red_batch_5`, `Crème teint 3` → `crème_teint_3`), with a note."""
    stem = path.stem
    name = stem
    if not _NAME.fullmatch(stem) or stem.startswith("."):
        name = _safe_name(stem)
    if not name:
        raise InputError(f"the file name {path.name!r} has no letters or digits to name the "
                         "material: add a line '# name: NAME' to the file", path)
    if len(name) > MAX_NAME:
        raise InputError(f"the material name from the file name is {len(name)} characters, "
                         f"more than {MAX_NAME}: add a line '# name: NAME' to the file", path)
    if name != stem:
        notes.append(f"{path}: the file name is not a material name (letters, digits, '.', "
                     f"'_', '+', '-'): named it '{name}' (set it with '# name: NAME')")
    return name


def _wavelengths_nm(wl, column, path, numbers):
    """The wavelength column in nm (µm when all under 10 or the header says so), checked."""
    notes = []
    unit = (WAVELENGTH_HEADER.fullmatch(column)["unit"] or "").lower()
    micrometres = unit not in ("", "nm")
    if not micrometres and np.all(wl < 10):
        micrometres = True
        notes.append(f"{path}: wavelengths are all under 10: read as µm (x 1000 to nm)")
    if micrometres:
        wl = wl * 1000.0
    lo, hi = WAVELENGTH_RANGE_NM
    bad = np.flatnonzero((wl < lo) | (wl > hi))
    if bad.size:
        shown = wl[bad[0]] / 1000 if micrometres else wl[bad[0]]
        units = "µm" if micrometres else "nm"
        raise InputError(
            f"wavelength {shown:g} {units} is outside {lo:g}-{hi:g} nm (nm and µm mixed? "
            f"give all in nm, or all in µm)", path, numbers[bad[0]], column)
    bad = np.flatnonzero(np.diff(wl) <= 0)
    if bad.size:
        raise InputError(
            f"wavelengths must increase (or all decrease), got "
            f"{_shown(wl, bad[0], micrometres)} then "
            f"{_shown(wl, bad[0] + 1, micrometres)}", path, numbers[bad[0] + 1], column)
    return wl, notes


def _shown(wl, i, micrometres):
    return f"{wl[i] / 1000:g}" if micrometres else f"{wl[i]:g}"


def _column_of(columns, role):
    return next(name for name, (kind, _) in columns.items() if kind == role)


def _is_radiance(name: str) -> bool:
    short = _canonical(name)
    return short == "E" or short.startswith("E_")


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _positive(value, path, line, column=None, scale=1.0, key=None) -> float:
    """A thickness in mm (`value` times `scale`: 1e-3 for µm), checked; a decimal comma is
    read as a point (one number alone: no column break to confuse it with). `column`: the
    header's, or `key`: a `# key:` line's."""
    try:
        x = float(_one_number(value)) * scale
    except ValueError:
        x = math.nan
    if not (math.isfinite(x) and 0 < x <= MAX_THICKNESS_MM):
        raise InputError(f"thickness must be a positive number of mm (at most "
                         f"{MAX_THICKNESS_MM:g}), got {value!r}", path, line, column, key)
    return x


# A percent unit after a reading column's name: "R_inf (%)", "R_g [%]", "R_g %".


def _canonical(name: str) -> str:
    """A reading column's name in the format's spelling: spaces as `_` (`R 0.05 mm` →
    `R_0.05_mm`), `E_R_…` as `E_…`, `∞` as `inf`."""
    short = PERCENT_UNIT.sub("", name.strip())  # "R_inf (%)"
    short = re.sub(r"\s+", "_", short).replace("∞", "inf")
    short = "E_" + short[4:] if short.startswith("E_R_") else short
    return {"Rinf": "R_inf", "Rg": "R_g", "Einf": "E_inf", "Eg": "E_g"}.get(short, short)


def _classify(header, path, line, bare_thickness):
    """Map each header name to (role, thickness); role is thin, inf, g or white."""
    expected = ("expected R_<X>mm (or R_<X>um), R, R_inf, R_g (or E_… and E_white); skip "
                "other columns with '# ignore: NAME' or --ignore")
    columns: dict[str, tuple[str, float]] = {}
    seen: dict[tuple[str, float], str] = {}
    for name in header[1:]:
        if is_wavelength_column(name):
            raise InputError("a second wavelength column", path, line, name)
        short = _canonical(name)
        if short in ("R_inf", "E_inf"):
            role = ("inf", 0.0)
        elif short in ("R_g", "E_g"):
            role = ("g", 0.0)
        elif short == "E_white":
            role = ("white", 0.0)
        elif short in ("R", "E"):
            if bare_thickness is None:
                raise InputError(
                    "a bare thin-layer column needs a thickness: add '# thickness_mm: X' "
                    "or pass --thickness", path, line, name,
                )
            role = ("thin", bare_thickness)
        elif (m := THIN_COLUMN.match(short)) and _is_float(_one_number(m["x"])):
            role = ("thin", _positive(m["x"], path, line, name,
                                      1.0 if m["unit"] == "mm" else 1e-3))
        else:
            raise InputError(f"unknown column; {expected}", path, line, name)
        if role in seen:
            raise InputError(f"the same quantity as column '{seen[role]}'", path, line, name)
        seen[role] = name
        columns[name] = role
    roles = {kind for kind, _ in columns.values()}
    for kind, what in (("thin", "R_<X>mm"), ("inf", "R_inf"), ("g", "R_g")):
        if kind not in roles:
            raise InputError(f"missing column {what}; {expected}", path, line)
    radiance = [n for n, (kind, _) in columns.items() if _is_radiance(n) and kind != "white"]
    if radiance and "white" not in roles:
        raise InputError("radiance columns need E_white (the white standard)", path, line,
                         radiance[0])
    reflectance = [n for n in columns if not _is_radiance(n)]
    if radiance and reflectance:  # an E column relabelled R_inf would fit "perfectly"
        raise InputError("a reflectance among radiance columns (E_..., E_white): a file's "
                         "readings are all of one kind; name it E_... if it holds radiance, "
                         "or give reflectances (R = E / E_white) throughout", path, line,
                         reflectance[0])
    return columns


def _one_number(text: str) -> str:
    """A lone number's text with a decimal comma made a point (`0,05`)."""
    text = text.strip()
    return text.replace(",", ".") if DECIMAL_COMMA.fullmatch(text) else text


def _fraction(value, path, line, key) -> float:
    """A `# key:` value that must be a reflectance in (0, 1]."""
    try:
        x = float(_one_number(value))
    except ValueError:
        x = math.nan
    if not (math.isfinite(x) and 0 < x <= 1):
        raise InputError(f"expected a reflectance in (0, 1], got {value!r}", path, line,
                         key=key)  # a `# key:` line's, not a column
    return x


def _reflectances(data, header, columns, path, numbers, percent, notes, white_R=1.0,
                  marked=()):
    """Reflectance per role (thin columns by name), checked to lie in [0, 1]. Reflectance
    columns are read as percent when `percent` (`--percent`), when their header says % (the
    `marked` ones, each alone, even where all its readings are below 1, as a black card's
    can be; one `R_inf (%)` does not make every column percent), or when the median of
    the others is above 1.5 (a note is added to `notes`). `--percent` on readings all at
    most 1 is refused (`check_percent`)."""
    index = {name: i + 1 for i, name in enumerate(header[1:])}
    for name in columns:
        if _is_radiance(name):
            values = data[:, index[name]]
            # below 0 is left to R = E / E_white's test: a dark-corrected reading's noise
            bad = np.flatnonzero(np.abs(values) > MAX_RADIANCE)
            if bad.size:
                raise InputError(f"radiance must be in [0, {MAX_RADIANCE:g}], got "
                                 f"{values[bad[0]]:g}", path, numbers[bad[0]], name)
    white = None
    white_name = next((n for n, (kind, _) in columns.items() if kind == "white"), None)
    if white_name is not None:
        white = data[:, index[white_name]]
        bad = np.flatnonzero(white <= 0)
        if bad.size:
            raise InputError(f"the white standard must be > 0, got {white[bad[0]]:g}",
                             path, numbers[bad[0]], white_name)
    plain = [index[n] for n in columns if not _is_radiance(n) and n not in marked]
    if plain and percent:
        check_percent(data[:, plain], path)
    if plain and not percent:
        values = data[:, plain]
        if np.median(values) > PERCENT_MEDIAN:  # then [0, 100] is checked below
            percent = True
            notes.append(f"{path}: reflectances have a median of {np.median(values):.3g}: read "
                         "as percent (/ 100)")
        elif marked:  # some say %, these do not, and read either way: 0.12 beside R_inf (%)
            unmarked = [n for n in columns if not _is_radiance(n) and n not in marked]
            raise InputError(  # a guess is wrong for some: a black card's 0.6 % read as 0.6
                f"column '{marked[0]}' says %, column{'s' if len(unmarked) > 1 else ''} '"
                + "', '".join(unmarked) + f"' {'do' if len(unmarked) > 1 else 'does'} not, "
                f"and their readings (median {np.median(values):.3g}) could be fractions or "
                "percent: give each column its unit (R_g (%)), or pass --percent if all are "
                "percent", path)
    out = {}
    for name, (kind, _) in columns.items():
        if kind == "white":
            continue
        values = data[:, index[name]]
        if _is_radiance(name):
            values = values / white * white_R
            what, scale = ("R = E / E_white must be in [0, 1]" if white_R == 1.0 else
                           f"R = E / E_white × {white_R:g} must be in [0, 1]"), 1.0
        elif percent or name in marked:
            what, scale = "reflectance in percent must be in [0, 100]", 100.0
        else:
            what, scale = "reflectance must be in [0, 1]", 1.0
        values = values / scale
        noise = (values < 0) & (values >= -NEGATIVE_NOISE)
        if noise.any():  # a dark-corrected reading of a black card: noise about 0
            notes.append(f"{path}: column '{name}': {int(noise.sum())} reading"
                         f"{'s' if noise.sum() > 1 else ''} below 0 (down to "
                         f"{values[noise].min() * scale:g}, within the "
                         f"{NEGATIVE_NOISE * scale:g} of noise) read as 0")
            values = np.where(noise, 0.0, values)
        bad = np.flatnonzero((values < 0) | (values > 1))
        if bad.size:
            hint = ("" if percent or name in marked or _is_radiance(name)
                    else " (percent data? use --percent)")
            if values[bad[0]] < 0:  # percent would not explain a reading of -0.0012
                hint = (f" (below the -{NEGATIVE_NOISE * scale:g} read as noise: "
                        "reflectances cannot be negative)")
            raise InputError(f"{what}, got {values[bad[0]] * scale:g}{hint}",
                             path, numbers[bad[0]], name)
        out[name if kind == "thin" else kind] = values
    return out
