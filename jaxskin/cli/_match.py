"""`jaxskin match`: the concentrations of given materials (and a film's thickness) whose
two-constant Kubelka–Munk mixture best matches a target spectrum or CIELAB colour
(`jaxskin.fitting.match`)."""

from __future__ import annotations

import math
import time
from pathlib import Path

from ..io import InputError
from ..outputs import Outputs, check_name, slug
from ._mix import add_density, densities
from ._options import no_report, number, saunderson, seed
from ._process import Run, print_written
from ._terminal import note, warn

__all__ = ["add_parser", "parse_lab", "run"]


def add_parser(sub) -> None:
    """The `jaxskin match` subcommand and its options."""
    m = sub.add_parser(
        "match",
        help="find the mixture of calibrated materials that matches a target colour",
        description="Computer colour matching: the volume fractions (>= 0, summing to 1; the "
        "base is one of the components) of the materials in --from whose two-constant "
        "Kubelka-Munk mixture best matches TARGET.csv's reflectance spectrum (wavelength_nm "
        "and one column R, 0-1; or a table of several spectra with --spectrum, e.g. the NIST "
        "skin file's subject_38), or a CIELAB colour (--lab). The mixture is opaque, unless "
        "--background is given: then a film over it, of --thickness or of the thickness "
        "that matches best. Colour is CIELAB under D65 with the CIE 1964 10-degree observer "
        "(the colour-matching industry's convention; --observer 2 for the renderer's), "
        "differences CIEDE2000; a spectral target's match also reports its metamerism "
        "(dE2000 under illuminant A and with the other observer). The loss is "
        "dE*ab^2 + W^2 (100 x RMS reflectance difference)^2 (W = --spectral-weight): the "
        "colour first, the spectrum to choose the least metameric of mixtures of the same "
        "colour. Levenberg-Marquardt (optimistix, float64) from several starts. Writes "
        "DIR/<TARGET>_match.json (concentrations by material name, thickness_mm where a film, "
        "dE2000) and DIR/<TARGET>_match.png (target and match spectra, swatches). A target "
        "the components cannot reach (dE2000 above 1) gets the closest match (by the "
        "loss), and a warning saying so.",
    )
    m.add_argument("target", nargs="?", metavar="TARGET.csv",
                   help="the target reflectance spectrum (or give --lab instead)")
    m.add_argument("--from", dest="components", required=True, metavar="A.json,B.json,...",
                   help="the components: material files (jaxskin calibrate's JSON with S, K "
                   "per mm) or shipped materials' names, separated by commas")
    m.add_argument("-o", "--output", required=True, metavar="DIR",
                   help="folder for <TARGET>_match.json and .png (created if missing); with "
                   "--spectrum, <TARGET>_<SPECTRUM>_match.*")
    m.add_argument("--lab", metavar="L,a,b",
                   help="a target colour in CIELAB (D65, the --observer's white) instead of "
                   "TARGET.csv")
    m.add_argument("--name", metavar="NAME",
                   help="the outputs' stem instead of TARGET's (default for --lab: lab)")
    m.add_argument("--spectrum", metavar="COLUMN",
                   help="which spectrum of a TARGET.csv that has several (a column name, or "
                   "subject_<k> in the NIST skin file)")
    m.add_argument("--percent", action="store_true",
                   help="TARGET.csv's reflectance is in percent (0-100) instead of 0-1 "
                   "(without it, a median above 1.5 is read as percent, with a note)")
    m.add_argument("--background", metavar="R|BG.csv",
                   help="match a film over this opaque background: a reflectance (0-1) or a "
                   "CSV of one spectrum (wavelength_nm, R); without it the mixture is opaque")
    m.add_argument("--thickness", metavar="MM|fit", default=None,
                   help="the film's thickness in mm, or 'fit' (the default with "
                   "--background): fitted within 0.0001-10 mm; needs --background")
    m.add_argument("--spectral-weight", type=number(lo=0.0, hi=100.0), default=0.05,
                   metavar="W", help="weight W of the spectral term, 0-100 (0.05: at 5 %% RMS "
                   "reflectance difference the spectrum counts like dE 0.25; 0: colour only); "
                   "unused with --lab")
    m.add_argument("--observer", type=int, choices=(10, 2), default=10,
                   help="the CIE standard observer in degrees: 10 (default; colour matching's "
                   "convention) or 2 (what the renderer and fit-skin use)")
    m.add_argument("--starts", type=number(int, 1, 256), default=12, metavar="S",
                   help="starts, 1-256: equal shares, each component dominant, then random (12)")
    saunderson(m, "the mixture's body reflectance is compared with the target after the "
               "correction, and a --background as read the same way, as calibrate --saunderson "
               "reads such readings; recorded in the JSON")
    seed(m)
    add_density(m, "the match also gives its recipe by weight (concentrations_by_weight)")
    no_report(m, "JSON")


def parse_lab(text: str) -> tuple[float, float, float]:
    """`L,a,b` → three floats; `InputError` unless L is in 0-100 and a, b in ±200."""
    parts = text.split(",")
    try:
        L, a, b = (float(p) for p in parts)
    except ValueError:
        L = a = b = math.nan
    ok = all(math.isfinite(v) for v in (L, a, b)) and 0 <= L <= 100 and max(abs(a), abs(b)) <= 200
    if len(parts) != 3 or not ok:
        raise InputError(f"--lab expects L,a,b (L 0-100, a and b within +-200), got {text!r}")
    return L, a, b


def _thickness(args):
    """`None` (opaque), "fit" or a number of mm, from --thickness and --background."""
    if args.thickness is not None and args.background is None:
        raise InputError("--thickness needs --background (the film lies over it); without "
                         "--background the mixture is matched opaque")
    if args.background is None:
        return None
    if args.thickness in (None, "fit"):
        return "fit"
    try:
        x = float(args.thickness)
    except ValueError:
        x = math.nan
    if not (math.isfinite(x) and 0 < x <= 10):
        raise InputError(f"--thickness expects a number of mm in (0, 10] or 'fit', got "
                         f"{args.thickness!r}")
    return x


def _read_target(args, notes):
    """`(stem, wavelengths, R)` of TARGET.csv's chosen spectrum, or `(stem, None, None)`."""
    from ..formats import read_spectra

    if (args.target is None) == (args.lab is None):
        raise InputError("give a target: TARGET.csv or --lab L,a,b (one of them)")
    if args.target is None:
        if args.spectrum is not None:
            raise InputError("--spectrum chooses a column of TARGET.csv; with --lab there is "
                             "none")
        return args.name or "lab", None, None
    names, wl, R = read_spectra(args.target, percent=args.percent or None, notes=notes)
    stem = slug(Path(args.target).stem)
    if args.spectrum is not None:
        if args.spectrum not in names:
            shown = ", ".join(names[:5]) + (", ..." if len(names) > 5 else "")
            raise InputError(f"--spectrum {args.spectrum!r} is not a spectrum of this file "
                             f"(it has {shown})", args.target)
        k = names.index(args.spectrum)
        stem = f"{stem}_{slug(args.spectrum)}"
    elif len(names) > 1:
        shown = ", ".join(names[:5]) + (", ..." if len(names) > 5 else "")
        raise InputError(f"{len(names)} spectra ({shown}); choose one with --spectrum",
                         args.target)
    else:
        k = 0
    return args.name or stem, wl, R[k]


def _read_background(args, notes):
    from ..formats import read_spectra

    text = args.background
    if text is None:
        return None
    try:
        v = float(text)
    except ValueError:
        v = None
    if v is not None:
        if not (math.isfinite(v) and 0 <= v <= 1):
            raise InputError(f"--background expects a reflectance in [0, 1] or a CSV file, "
                             f"got {text!r}")
        return v
    if not Path(text).is_file():
        raise InputError("--background: no such file (a reflectance 0-1 or a CSV of one "
                         "spectrum)", text)
    names, wl, R = read_spectra(text, percent=None, notes=notes)
    if len(names) != 1:
        raise InputError(f"--background: expected one spectrum, got {len(names)}", text)
    return wl, R[0]


def run(args, record: Run) -> int:
    """Check everything, fit the match, write its JSON and report."""
    from ..cosmetics import material_path

    items = [s.strip() for s in args.components.split(",")]
    if not all(items):
        raise InputError(f"--from expects material files separated by commas, got "
                         f"{args.components!r}")
    if args.lab is not None:
        target_lab = parse_lab(args.lab)
    thickness = _thickness(args)
    notes: list[str] = []
    stem, wl, R = _read_target(args, notes)
    check_name(stem, key="--name")
    background = _read_background(args, notes)
    from ..fitting import match

    paths = [material_path(p) for p in items]
    comps = match.read_components(paths)
    rho = densities(args.density, comps.names)
    inputs = [*paths, args.target, args.background if isinstance(background, tuple) else None]
    outputs = Outputs(args.output, inputs)
    json_path = outputs.plan(f"{stem}_match.json", "the match")
    png_path = None if args.no_report else outputs.plan(f"{stem}_match.png", "the report")
    record.outputs.append(outputs)
    for line in notes + comps.notes:
        note(line)
    record.stage = "matching"
    t0 = time.perf_counter()
    result = match.fit(comps, wl, R, None if args.lab is None else target_lab, thickness,
                       background, args.spectral_weight, args.starts, args.seed, args.observer,
                       args.saunderson or (0.0, 0.0))
    seconds = time.perf_counter() - t0
    record.stage = f"writing {json_path.name}"
    from ..fitting.match_report import match_json, write_report
    from ..formats import write_json

    target = args.target if args.lab is None else None
    write_json(match_json(result, comps, target=target, spectrum=args.spectrum,
                          background=args.background, spectral_weight=args.spectral_weight,
                          starts=args.starts, seed=args.seed, seconds=seconds, densities=rho),
               json_path)
    outputs.done(json_path)
    if png_path is not None:
        record.stage = f"writing {png_path.name}"
        write_report(result, comps, png_path, title=stem)
        outputs.done(png_path)
    _say(result, items, seconds, rho)
    print_written(outputs)
    return 0


def _say(result, items, seconds: float, rho=None) -> None:
    """The concentrations, ΔE and the mix command line; a warning if out of reach."""
    import jax
    import numpy as np

    from .. import mixture

    wide = max(12, *(len(n) for n in result.names))
    shares = result.concentrations
    if rho is not None:
        with jax.enable_x64(True):
            shares = np.asarray(mixture.weight_fractions(shares, np.array(
                [rho[n] for n in result.names])))
    print(f"{'':<{wide}} {'volume':>8}" + (f" {'weight':>8}" if rho else ""))
    for n, c, w in zip(result.names, result.concentrations, shares, strict=True):
        print(f"{n:<{wide}} {c:8.4f}" + (f" {w:8.4f}" if rho else ""))
    film = "" if result.thickness_mm is None else f", film {result.thickness_mm * 1000:.2f} µm"
    rms = "" if result.rms is None else f", RMS reflectance difference {result.rms:.4f}"
    print(f"dE2000 {result.dE2000:.3f} (D65, {result.observer}°){rms}{film}; {result.steps} "
          f"steps{'' if result.converged else ' (not converged)'}, {seconds:.1f} s")
    if result.metamerism:
        print("metamerism: " + ", ".join(f"{k} {v:.2f}" for k, v in result.metamerism.items()))
    recipe = " ".join(f"{p}:{c:.4f}" for p, c in zip(items, shares, strict=True))
    if rho:
        recipe += "".join(f" --density {n}={r:g}" for n, r in rho.items())
    print(f"to make it: jaxskin mix {recipe} -o DIR")
    if result.thickness_fitted and result.hides_background:
        warn(f"the matched film ({result.thickness_mm * 1000:.3g} µm) hides the background: "
             "its reflectance is the opaque mixture's, so the thickness is not determined "
             "by the target (any thicker film matches as well)")
    if not result.in_gamut:
        from ..fitting.match import GAMUT_DE

        warn(f"the target is outside what these components can mix: the closest match is "
             f"dE2000 {result.dE2000:.2f} (over {GAMUT_DE:g}, a visible difference); add a "
             "component that moves towards it (see the report)")
