"""Reading one measurement CSV (`read_measurement`): its table, its notes, its name."""

from __future__ import annotations

import dataclasses
import fnmatch
import math
import re
from pathlib import Path

import numpy as np

from jaxskin.formats import (
    PERCENT_UNIT,
    decimal_comma_note,
    drop_repeats,
    is_wavelength_column,
    read_table,
)
from jaxskin.io import InputError
from jaxskin.outputs import MAX_NAME

from ._columns import (
    MAX_THICKNESS_MM,
    classify,
    column_of,
    fraction,
    is_radiance,
    is_reading,
    positive,
    takes_thickness,
)
from ._readings import reflectances, wavelengths_nm

_NAME = re.compile(r"[\w.+-]+")  # a material name (it names the output files)
# Thin-layer thicknesses outside this are named in a note: cosmetic films are µm to a
# tenth of a mm; R_3mm for R_3um fits as well with S, K 1000× too small.
USUAL_THICKNESS_MM = (1e-4, 1.0)


@dataclasses.dataclass(frozen=True)
class Measurement:
    """One cosmetic's reflectance measurements, all on one wavelength grid.

    **Fields:** `path`, `name`, `wavelength_nm (n,)`, `thickness_mm (m,)`, `R (m, n)` of the
    thin layers over the background, `R_inf (n,)`, `R_g (n,)`, `columns`: the CSV column
    each thin layer came from, `header_line`: the header's line number in the file, `notes`:
    what the reader inferred (µm wavelengths, percent reflectance), one line each.

    A contrast card (drawdown; ASTM D2805, ISO 6504-3) has `R_g_white (n,)`, the card's white
    part, and then `R_g` is its black part; `R` holds each film over the black part and over
    the white one (`over` names which, per row; thinnest film first), `R_inf` may be None,
    and `thickness_known` is False when the film's thickness was not given (its
    `thickness_mm` is then 1: one film, S and K come out as S·X and K·X).
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
    R_g_white: np.ndarray | None = None
    over: tuple[str, ...] = ()
    thickness_known: bool = True

    @property
    def is_card(self) -> bool:
        """Whether this is a contrast card: films over a black and a white background."""
        return self.R_g_white is not None

    @property
    def backgrounds(self) -> np.ndarray:
        """`(m, n)`: the background under each row of `R`."""
        if not self.is_card:
            return np.broadcast_to(self.R_g, self.R.shape)
        return np.stack([self.R_g if o == "black" else self.R_g_white for o in self.over])


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

    wl, notes = wavelengths_nm(data[:, 0], header[0], path, numbers)
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
    said = [n for n in columns if PERCENT_UNIT.search(n) and not is_radiance(n)]
    if said and not percent:  # the header says so: not left to the median's guess
        these = "', '".join(said)
        notes.append(f"{path}: column{'s' if len(said) > 1 else ''} '{these}' say"
                     f"{'' if len(said) > 1 else 's'} %: read as percent (/ 100)")
    reflectance = reflectances(data, header, columns, path, numbers, percent, notes, white,
                                marked=said)
    name = _material_name(path, meta, notes)
    if "g_black" in reflectance:
        return _card(path, name, wl, columns, reflectance, header_line, numbers, notes)
    thin = sorted((x, name) for name, (kind, x) in columns.items() if kind == "thin")
    R = np.stack([reflectance[name] for _, name in thin])
    R_inf, R_g = reflectance["inf"], reflectance["g"]
    if np.all(np.abs(R_g - R_inf) <= 1e-12):
        raise InputError(
            "R_g equals R_inf at every wavelength: the background must differ from the opaque "
            "layer (a black or white card)", path, header_line, column_of(columns, "g"),
        )
    return Measurement(
        path=path, name=name, wavelength_nm=wl, thickness_mm=np.array([x for x, _ in thin]),
        R=R, R_inf=R_inf, R_g=R_g, columns=tuple(n for _, n in thin), header_line=header_line,
        notes=tuple(notes),
    )


def _card(path, name, wl, columns, reflectance, header_line, numbers, notes) -> Measurement:
    """A contrast card's `Measurement`, its readings checked: the white part brighter than
    the black at every band, and no film brighter over black than over white everywhere."""
    black, white = reflectance["g_black"], reflectance["g_white"]
    bad = np.flatnonzero(white <= black)
    if bad.size:
        i = bad[0]
        raise InputError(f"the card's white part ({white[i]:g}) is not brighter than its black "
                         f"part ({black[i]:g}) at {wl[i]:g} nm: R_g_black and R_g_white "
                         "swapped?", path, numbers[i], column_of(columns, "g_white"))
    films = {}
    for col, (kind, x) in columns.items():
        if kind in ("over_black", "over_white"):
            films.setdefault(x, {})[kind[5:]] = col
    known = None not in films
    rows, over, thickness, names = [], [], [], []
    for x in sorted(films, key=lambda v: -1.0 if v is None else v):
        on_black, on_white = (reflectance[films[x][p]] for p in ("black", "white"))
        if np.all(on_black > on_white):
            raise InputError("the film is brighter over the card's black part than over its "
                             f"white part at every band ('{films[x]['white']}' is the other): "
                             "the film's columns swapped?", path, header_line,
                             films[x]["black"])
        for part, values in (("black", on_black), ("white", on_white)):
            rows.append(values)
            over.append(part)
            thickness.append(1.0 if x is None else x)
            names.append(films[x][part])
    if not known:
        notes.append(f"{path}: the film's thickness is not given: S and K are fitted as S·X "
                     "and K·X of the film as measured (S_film, K_film); give it (R_over_black_"
                     "<X>mm, --thickness or '# thickness_mm:') for S and K per mm")
    return Measurement(
        path=path, name=name, wavelength_nm=wl, thickness_mm=np.array(thickness),
        R=np.stack(rows), R_inf=reflectance.get("inf"), R_g=black, columns=tuple(names),
        header_line=header_line, notes=tuple(notes), R_g_white=white, over=tuple(over),
        thickness_known=known,
    )


def _header_columns(path, header, meta, line, ignore, thickness_mm):
    """`{"ignored": the columns to skip, "comment": the `# thickness_mm:` line's thickness
    or None, "columns": the others classified (`classify`)}`, from the header row and the
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
        comment = positive(value, path, number, key="thickness_mm")
    bare = thickness_mm if thickness_mm is not None else comment
    columns = classify([n for n in header if n not in ignored], path, line, bare)
    return {"comment": comment, "columns": columns, "ignored": ignored}


def _read_table(path, on_header):
    """The measurement's table (`read_table` with this format's header and `# key:` lines);
    a file with no header row that is laid out in another way is named as such
    (`_other_layout`)."""
    try:
        return read_table(path, is_wavelength_column, "wavelength_nm,R_<X>mm,...,R_inf,R_g",
                          min_rows=2, other_column=is_reading,
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
        if kind in ("thin", "over_black", "over_white") and x is not None and not lo <= x <= hi:
            notes.append(f"{path}: column '{name}': a {x:g} mm film; cosmetic films are "
                         f"{lo * 1000:g} µm to {hi:g} mm thick, and S, K scale as 1 / "
                         f"thickness: {'µm (R_<X>um)' if x > hi else 'mm'} meant?")
    if comment_thickness is not None:  # said, so not dropped in silence
        value, number = meta["thickness_mm"]
        said = f"{path}:{number}: '# thickness_mm: {value}'"
        if not any(takes_thickness(n) for n in columns):
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
        white = fraction(value, path, number, "white_reflectance")
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
                and not any(is_reading(c) for c in cells[1:])):
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
        if later and any(is_reading(c) for c in cells):
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
