"""A measurement table's columns: each header cell's role (thin layer, opaque layer,
background, white standard) and thickness, and the values of its `# key:` lines."""

from __future__ import annotations

import math
import re

from jaxskin.formats import DECIMAL_COMMA, PERCENT_UNIT, is_wavelength_column
from jaxskin.io import InputError

# A thin layer's column, after `canonical`: R_0.05mm, R_0.05_mm (from "R 0.05 mm"),
# R0.05mm, R_50um, R_50µm; E_… for radiance.
THIN_COLUMN = re.compile(r"^(?:R|E)_?(?P<x>.+?)_?(?P<unit>mm|um|µm|μm)$")
MAX_THICKNESS_MM = 100.0  # a cosmetic layer is µm to a few mm; beyond this it is a typo
# A contrast card (drawdown) film's column, after `canonical`: R_over_black,
# R_over_white_0.05mm, R_over_black_50um, E_over_white (the thickness optional).
CARD_COLUMN = re.compile(r"^(?:R|E)_?(?i:over)_?(?P<part>(?i:black|white))(?:_?(?P<x>[^_]+?)_?"
                         r"(?P<unit>mm|um|µm|μm))?$")
# The card's two parts alone: R_g_black, R_g_white (Rg_black, R g white).
CARD_PART = re.compile(r"^(?:R|E)_?g_?(?P<part>(?i:black|white))$")
# Column roles of the contrast-card layout: a film over the card's black or white part, and
# the parts alone.
CARD_ROLES = ("over_black", "over_white", "g_black", "g_white")


def is_reading(name: str) -> bool:
    """Whether a header cell may name a reading: reflectance `R…` or radiance `E…`."""
    return name.startswith(("R", "E"))


def column_of(columns, role):
    """The name of the column `classify` gave `role`."""
    return next(name for name, (kind, _) in columns.items() if kind == role)


def is_radiance(name: str) -> bool:
    """Whether a reading column holds radiance (`E`, `E_…`, `E_R_…`), not reflectance."""
    short = canonical(name)
    return short == "E" or short.startswith("E_")


def takes_thickness(name: str) -> bool:
    """Whether a column takes its thickness from `--thickness` or `# thickness_mm:`: a bare
    `R` (or `E`), or a contrast card's film without one (`R_over_black`)."""
    short = canonical(name)
    return short in ("R", "E") or bool((m := CARD_COLUMN.match(short)) and m["x"] is None)


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def positive(value, path, line, column=None, scale=1.0, key=None) -> float:
    """A thickness in mm (`value` times `scale`: 1e-3 for µm), checked; a decimal comma is
    read as a point (one number alone: no column break to confuse it with). `column`: the
    header's, or `key`: a `# key:` line's."""
    try:
        x = float(one_number(value)) * scale
    except ValueError:
        x = math.nan
    if not (math.isfinite(x) and 0 < x <= MAX_THICKNESS_MM):
        raise InputError(f"thickness must be a positive number of mm (at most "
                         f"{MAX_THICKNESS_MM:g}), got {value!r}", path, line, column, key)
    return x


def canonical(name: str) -> str:
    """A reading column's name in the format's spelling: spaces as `_` (`R 0.05 mm` →
    `R_0.05_mm`), `E_R_…` as `E_…`, `∞` as `inf`."""
    short = PERCENT_UNIT.sub("", name.strip())  # "R_inf (%)"
    short = re.sub(r"\s+", "_", short).replace("∞", "inf")
    short = "E_" + short[4:] if short.startswith("E_R_") else short
    return {"Rinf": "R_inf", "Rg": "R_g", "Einf": "E_inf", "Eg": "E_g"}.get(short, short)


def classify(header, path, line, bare_thickness):
    """Map each header name to (role, thickness); role is thin, inf, g or white, or for a
    contrast card over_black, over_white (thickness None: not known), g_black, g_white."""
    expected = ("expected R_<X>mm (or R_<X>um), R, R_inf, R_g, or a contrast card's "
                "R_over_black, R_over_white, R_g_black, R_g_white (or E_… and E_white); skip "
                "other columns with '# ignore: NAME' or --ignore")
    columns: dict[str, tuple[str, float]] = {}
    seen: dict[tuple[str, float], str] = {}
    for name in header[1:]:
        if is_wavelength_column(name):
            raise InputError("a second wavelength column", path, line, name)
        short = canonical(name)
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
        elif m := CARD_PART.match(short):
            role = ("g_" + m["part"].lower(), 0.0)
        elif m := CARD_COLUMN.match(short):
            x = bare_thickness
            if m["x"] is not None:
                if not _is_float(one_number(m["x"])):
                    raise InputError(f"unknown column; {expected}", path, line, name)
                x = positive(m["x"], path, line, name, 1.0 if m["unit"] == "mm" else 1e-3)
            role = ("over_" + m["part"].lower(), x)
        elif (m := THIN_COLUMN.match(short)) and _is_float(one_number(m["x"])):
            role = ("thin", positive(m["x"], path, line, name,
                                      1.0 if m["unit"] == "mm" else 1e-3))
        else:
            raise InputError(f"unknown column; {expected}", path, line, name)
        if role in seen:
            raise InputError(f"the same quantity as column '{seen[role]}'", path, line, name)
        seen[role] = name
        columns[name] = role
    roles = {kind for kind, _ in columns.values()}
    if roles & set(CARD_ROLES):
        _check_card(columns, path, line)
    else:
        for kind, what in (("thin", "R_<X>mm"), ("inf", "R_inf"), ("g", "R_g")):
            if kind not in roles:
                raise InputError(f"missing column {what}; {expected}", path, line)
    radiance = [n for n, (kind, _) in columns.items() if is_radiance(n) and kind != "white"]
    if radiance and "white" not in roles:
        raise InputError("radiance columns need E_white (the white standard)", path, line,
                         radiance[0])
    reflectance = [n for n in columns if not is_radiance(n)]
    if radiance and reflectance:  # an E column relabelled R_inf would fit "perfectly"
        raise InputError("a reflectance among radiance columns (E_..., E_white): a file's "
                         "readings are all of one kind; name it E_... if it holds radiance, "
                         "or give reflectances (R = E / E_white) throughout", path, line,
                         reflectance[0])
    return columns


def _check_card(columns, path, line) -> None:
    """A contrast card's columns: both parts of the card, each film over both, and no column
    of the one-background layout beside them."""
    other = [n for n, (kind, _) in columns.items() if kind in ("thin", "g")]
    if other:
        raise InputError("a column of the one-background layout (R_<X>mm, R, R_g) among a "
                         "contrast card's (R_over_black, R_over_white, R_g_black, R_g_white): "
                         "a file holds one layout; put the other in a file of its own", path,
                         line, other[0])
    roles = {kind for kind, _ in columns.values()}
    for part, partner in (("g_black", "g_white"), ("g_white", "g_black")):
        if part in roles and partner not in roles:
            name = column_of(columns, part)
            raise InputError(f"the card's {part[2:]} part without its {partner[2:]} part: a "
                             f"contrast card needs both R_g_black and R_g_white", path, line,
                             name)
    if "g_black" not in roles:
        raise InputError("films over a contrast card (R_over_black, R_over_white) need the "
                         "card's two parts alone: missing columns R_g_black and R_g_white",
                         path, line)
    films = {}
    for name, (kind, x) in columns.items():
        if kind in ("over_black", "over_white"):
            films.setdefault(x, {})[kind] = name
    if not films:
        raise InputError("a contrast card's parts but no film over them: expected "
                         "R_over_black and R_over_white (R_over_black_<X>mm, ... for each "
                         "thickness)", path, line)
    for x, parts in films.items():
        if len(parts) == 1:
            (kind, name), = parts.items()
            partner = "R_over_white" if kind == "over_black" else "R_over_black"
            at = "" if x is None else f" (the {x:g} mm film)"
            raise InputError(f"a film over one part of the card without its partner: no "
                             f"{partner} column{at}; each film is read over both the black "
                             "and the white part", path, line, name)
    if None in films and len(films) > 1:
        raise InputError("a film of unknown thickness beside films of known thickness: give "
                         "its thickness (R_over_black_<X>mm, --thickness or '# "
                         "thickness_mm:')", path, line, films[None]["over_black"])


def one_number(text: str) -> str:
    """A lone number's text with a decimal comma made a point (`0,05`)."""
    text = text.strip()
    return text.replace(",", ".") if DECIMAL_COMMA.fullmatch(text) else text


def fraction(value, path, line, key) -> float:
    """A `# key:` value that must be a reflectance in (0, 1]."""
    try:
        x = float(one_number(value))
    except ValueError:
        x = math.nan
    if not (math.isfinite(x) and 0 < x <= 1):
        raise InputError(f"expected a reflectance in (0, 1], got {value!r}", path, line,
                         key=key)  # a `# key:` line's, not a column
    return x
