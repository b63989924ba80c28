"""Spectra: the NIST skin reflectances, Prahl's haemoglobin extinction and the reflectance
spectra `jaxskin fit-skin` reads."""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from ..io import InputError, data_dir
from ..outputs import slug
from ._tables import (
    NEGATIVE_NOISE,
    PERCENT_MEDIAN,
    PERCENT_UNIT,
    WAVELENGTH_HEADER,
    check_percent,
    decimal_comma_note,
    drop_repeats,
    read_number,
    read_table,
)
from ._text import read_text, split_row

# ---------------------------------------------------------------- the NIST skin spectra

NIST_FILE = "nist_skin_reflectance_M38597.csv"
NIST_SUBJECTS = 100


@functools.cache
def nist_table() -> tuple[np.ndarray, np.ndarray]:
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
    wl, means = nist_table()
    return wl, means[subject - 1]


def nist_reflectance(subject: int, grid) -> np.ndarray:
    """Subject `subject`'s mean reflectance on `grid` (a `spectral.Grid`; host float64)."""
    return np.interp(grid.wavelengths, *nist_spectrum(subject))


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
    named `subject_k`). In the wide layout an empty cell is a missing reading (NaN in `R`:
    spectra measured over different ranges in one table). Reflectance in 0–1 (`percent`:
    0–100; `None`: percent when the median is above `PERCENT_MEDIAN`, as `calibrate`
    guesses, with a line appended to `notes`); wavelengths increasing, or all decreasing
    (then reversed, with a note).
    `InputError` names the file, line and column of anything else.
    """
    path = Path(path)
    notes = [] if notes is None else notes
    text = read_text(path, fallback="cp1252")
    lines = text.splitlines()
    header_at = None
    for i, raw in enumerate(lines):
        cells = split_row(raw.strip(), ",") if raw.strip() and not raw.startswith("#") else []
        if cells and _nm_column(cells[0]):
            header_at = i
            break
    if header_at is not None and "Average" in split_row(lines[header_at], ","):
        names, wavelengths, R = _nist_layout(path, lines, header_at)
        header_line, line_of, wl_name = header_at + 1, None, split_row(lines[header_at], ",")[0]
    else:
        t = read_table(path, _nm_column, "wavelength_nm,<spectrum name>,...", min_rows=2,
                       wavelength_first=True, missing=True)
        if len(t.header) < 2:
            raise t.error("no spectra: expected wavelength_nm and one column per spectrum")
        data, line_of = drop_repeats(t.data, t.lines, path, notes)
        names, wavelengths, R = t.header[1:], data[:, 0], data[:, 1:].T
        header_line, wl_name = t.header_line, t.header[0]
        if t.decimal_comma:
            notes.append(f"{path}: {decimal_comma_note(t.decimal_comma)}")
    if len(wavelengths) > 1 and np.all(np.diff(wavelengths) < 0):  # long ones first
        wavelengths, R = wavelengths[::-1], R[:, ::-1]
        line_of = None if line_of is None else list(line_of)[::-1]
        notes.append(f"{path}: wavelengths descend: read in increasing order")
    if np.any(np.diff(wavelengths) <= 0):
        row = int(np.flatnonzero(np.diff(wavelengths) <= 0)[0]) + 1
        raise InputError("wavelengths must increase (or all decrease)", path,
                         None if line_of is None else line_of[row], wl_name)
    columns = list(names)  # as the file spells them, for the messages
    names, marked = _percent_columns(path, names, R, header_line, notes)
    R, tops = _fractions(path, R, names, marked, percent, notes)
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


def _nist_layout(path, lines, header_at: int):
    """`(names, wavelengths, R)` of a file in the NIST skin file's layout, whose header is
    `lines[header_at]`: each `Average` column, named by the `Subject k` cell above it."""
    header = split_row(lines[header_at], ",")
    above = next((split_row(lines[j], ",") for j in range(header_at - 1, -1, -1)
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
        cells = split_row(raw.strip(), ",")
        if not raw.strip() or raw.startswith("#"):
            continue
        if len(cells) < len(header):
            raise InputError(f"{len(cells)} cells where the header has {len(header)}",
                             path, number)
        wl.append(read_number(cells[0], path, number, header[0]))
        rows.append([read_number(cells[c], path, number, f"{names[k]} Average")
                     for k, c in enumerate(columns)])
    if len(wl) < 2:
        raise InputError("needs at least 2 rows of spectra", path, header_at + 1)
    return names, np.asarray(wl), np.asarray(rows).T


def _percent_columns(path, names, R, header_line: int, notes: list):
    """`(names, marked)`: the spectra whose header says % (`Forearm A (%)`), named without
    it, as calibrate reads its columns (else the unit would stay in the names); such a
    column must hold percent, not fractions. A note names them."""
    columns = list(names)  # as the file spells them, for the messages
    marked = np.array([bool(PERCENT_UNIT.search(n)) for n in names])
    names = [PERCENT_UNIT.sub("", n) if m else n for n, m in zip(names, marked, strict=True)]
    for k in np.flatnonzero(marked):
        if not names[k]:
            raise InputError("a spectrum's name is its unit alone: name the column", path,
                             header_line, columns[k])
        if np.nanmax(R[k], initial=0.0) <= 1.0:  # no skin reflects under 1 % at every band
            raise InputError(f"says %, but every reading is at most 1 (median "
                             f"{np.nanmedian(R[k]):.3g}): these are fractions (0-1); remove the % "
                             "from the header", path, header_line, columns[k])
    if marked.any():
        said = [c for c, m in zip(columns, marked, strict=True) if m]
        these = "', '".join(said[:3])
        notes.append(f"{path}: column{'s' if len(said) > 1 else ''} '{these}'"
                     f"{' ...' if len(said) > 3 else ''} say{'' if len(said) > 1 else 's'} %: "
                     "read as percent (/ 100)")
    return names, marked


def _fractions(path, R, names, marked, percent, notes: list):
    """`(R as fractions, each spectrum's full scale: 1 or 100)`: the `marked` spectra and,
    with `percent` (or, when it is None, a median above `PERCENT_MEDIAN`), the others
    divided by 100; readings just below 0 (`NEGATIVE_NOISE`) read as 0, with a note."""
    rest = R[~marked]
    if percent is None:
        read = rest[np.isfinite(rest)]  # NaN: a missing reading
        percent = bool(read.size) and float(np.median(read)) > PERCENT_MEDIAN
        if percent:
            notes.append(f"{path}: reflectances have a median of {np.median(read):.3g}: read "
                         "as percent (/ 100; --percent says so)")
    elif percent and rest.size:
        check_percent(rest, path)
    tops = np.where(marked | bool(percent), 100.0, 1.0)
    R = R / tops[:, None]
    noise = (R < 0) & (R >= -NEGATIVE_NOISE)  # as calibrate reads them: -0.001 is noise
    for k in np.flatnonzero(noise.any(axis=1)):
        notes.append(f"{path}: spectrum '{names[k]}': {int(noise[k].sum())} reading"
                     f"{'s' if noise[k].sum() > 1 else ''} below 0 (down to "
                     f"{R[k][noise[k]].min() * tops[k]:g}, within the "
                     f"{NEGATIVE_NOISE * tops[k]:g} of noise) read as 0")
    return np.where(noise, 0.0, R), tops
