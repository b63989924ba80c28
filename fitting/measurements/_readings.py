"""A measurement table's readings: wavelengths in nm, and reflectances (from percent,
or from radiance over the white standard) checked to lie in [0, 1]."""

from __future__ import annotations

import numpy as np

from jaxskin.formats import (
    NEGATIVE_NOISE,
    PERCENT_MEDIAN,
    WAVELENGTH_HEADER,
    WAVELENGTH_RANGE_NM,
    check_percent,
)
from jaxskin.io import InputError

from ._columns import is_radiance

MAX_RADIANCE = 1e30  # any unit of radiance or counts; beyond this it is an overflow


def wavelengths_nm(wl, column, path, numbers):
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


def reflectances(data, header, columns, path, numbers, percent, notes, white_R=1.0,
                  marked=()):
    """Reflectance per role (thin columns by name), checked to lie in [0, 1]. Reflectance
    columns are read as percent when `percent` (`--percent`), when their header says % (the
    `marked` ones, each alone, even where all its readings are below 1, as a black card's
    can be; one `R_inf (%)` does not make every column percent), or when the median of
    the others is above 1.5 (a note is added to `notes`). `--percent` on readings all at
    most 1 is refused (`check_percent`)."""
    index = {name: i + 1 for i, name in enumerate(header[1:])}
    for name in columns:
        if is_radiance(name):
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
    plain = [index[n] for n in columns if not is_radiance(n) and n not in marked]
    if plain and percent:
        check_percent(data[:, plain], path)
    if plain and not percent:
        values = data[:, plain]
        if np.median(values) > PERCENT_MEDIAN:  # then [0, 100] is checked below
            percent = True
            notes.append(f"{path}: reflectances have a median of {np.median(values):.3g}: read "
                         "as percent (/ 100)")
        elif marked:  # some say %, these do not, and read either way: 0.12 beside R_inf (%)
            unmarked = [n for n in columns if not is_radiance(n) and n not in marked]
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
        if is_radiance(name):
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
            hint = ("" if percent or name in marked or is_radiance(name)
                    else " (percent data? use --percent)")
            if values[bad[0]] < 0:  # percent would not explain a reading of -0.0012
                hint = (f" (below the -{NEGATIVE_NOISE * scale:g} read as noise: "
                        "reflectances cannot be negative)")
            raise InputError(f"{what}, got {values[bad[0]] * scale:g}{hint}",
                             path, numbers[bad[0]], name)
        out[name if kind in ("thin", "over_black", "over_white") else kind] = values
    return out
