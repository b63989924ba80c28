"""`jaxskin calibrate`: Kubelka–Munk S(λ), K(λ) of cosmetics from spectroradiometer CSVs
(`jaxskin.fitting.km`), one material JSON and one report per file."""

from __future__ import annotations

import functools
import time

from .. import cluster
from ..outputs import Outputs, check_name
from ._options import no_report, number, saunderson
from ._process import Run, print_written
from ._terminal import note, warn

__all__ = ["add_parser", "run"]


def add_parser(sub) -> None:
    """The `jaxskin calibrate` subcommand and its options."""
    c = sub.add_parser(
        "calibrate",
        help="fit Kubelka–Munk S(λ), K(λ) of cosmetics to spectroradiometer CSVs",
        description="Fit scattering S(λ) and absorption K(λ) (per mm) of each cosmetic from a "
        "CSV of thin-layer (R_<X>mm), opaque (R_inf) and background (R_g) reflectances, or of "
        "a film drawn down over a contrast card (R_over_black, R_over_white, R_g_black, "
        "R_g_white; R_inf optional; without a thickness, S and K of the film as measured), "
        "or raw radiances (E_… and E_white). Writes OUTDIR/<name>.json (the material file the "
        "renderer reads) and OUTDIR/<name>.png (a report), and prints each material's "
        "contrast ratio, thickness for 98%% hiding and ΔE2000 over black vs white (ASTM "
        "D2805's backgrounds, D65, 10°). Every file is checked before any "
        "fit runs: one bad file writes nothing. The CSV format: docs/reference/formats.md.",
    )
    c.add_argument("files", nargs="+", metavar="FILE.csv", help="measurement CSVs")
    c.add_argument("-o", "--output", required=True, metavar="OUTDIR",
                   help="folder for <name>.json and <name>.png (created if missing)")
    c.add_argument("--thickness", type=number(above=0.0, hi=100.0), metavar="MM",
                   help="thickness in mm of a bare 'R' column or a contrast card's film "
                   "without one (R_over_black, R_over_white; overrides '# thickness_mm:'); "
                   "warned of when no file has one")
    saunderson(c, "the KM film and its backgrounds are then internal reflectances, the "
               "fit's residuals stay in the readings; recorded in the JSON")
    c.add_argument("--percent", action="store_true",
                   help="reflectance columns are in percent (0–100) instead of 0–1 (without "
                   "it, a file whose reflectances have a median above 1.5 is read as percent, "
                   "with a note)")
    c.add_argument("--white-reflectance", type=number(above=0.0, hi=1.0), metavar="R",
                   help="the white standard's certified reflectance (0-1; overrides '# "
                   "white_reflectance:'): radiance columns give R = E / E_white × R (default "
                   "1, Huang et al.'s barium sulfate)")
    c.add_argument("--ignore", action="append", default=[], metavar="COLUMN",
                   help="skip this column in every file (repeatable; a pattern such as "
                   "'SD_*' in quotes skips all that match): standard deviations, counts, "
                   "notes. A file can also say '# ignore: NAME, NAME' itself")
    # The bounds are fitting.km's MAX_SMOOTH and MAX_NOISE (not imported: that imports JAX,
    # and --help stays quick; tests/test_calibrate.py checks that they agree).
    c.add_argument("--smooth", type=number(lo=0.0, hi=1e6), default=0.0, metavar="W",
                   help="smoothness prior: neighbouring bands' log S and log K differ by about "
                   "1/W (a Gaussian prior weighed against readings of σ = --noise); 0 (default) "
                   "fits each band on its own; 20 allows about 5%% per band")
    c.add_argument("--noise", type=number(above=0.0, hi=0.5), default=None, metavar="σ",
                   help="standard deviation of one reflectance reading, > 0 and <= 0.5 "
                   "(default 0.002); a band is identifiable when some thin layer and the "
                   "background each differ from R_inf by more than 3σ; a fit whose RMS error "
                   "is above 3σ is warned of")
    c.add_argument("--extrapolate", choices=("hold", "linear"), default=None,
                   help="how the renderer may extend S, K beyond the measured wavelengths to "
                   "its 380-780 nm grid: hold the end values, or continue log S, log K "
                   "linearly; without it a material that does not cover the grid is refused "
                   "at render time (calibrate warns). The report draws the extension; "
                   "calibrate warns where it makes up over half the grid, or where 'linear' "
                   "carries S or K more than tenfold")
    no_report(c, "JSON")
    cluster.add_option(c, "file")


def run(args, record: Run) -> int:
    """Fit S(λ), K(λ) of each measurement file; write its material JSON and report."""
    from jaxskin.fitting import km as fit_km

    noise = fit_km.DEFAULT_NOISE if args.noise is None else args.noise
    outputs = Outputs(args.output, args.files)
    measurements, paths = _read_all(args, outputs, noise)
    record.outputs.append(outputs)

    from jaxskin.fitting.report import far_extrapolation, write_report
    from jaxskin.formats import write_json
    from jaxskin.spectral import Grid

    grid = Grid().wavelengths
    _warn_about_the_readings(args, measurements, grid, noise)

    rows, mismatched = [], []
    fit = functools.partial(fit_km.fit, smooth=args.smooth, noise=noise,
                            saunderson=args.saunderson)
    with cluster.pool(args.cluster) as pool:
        record.stage = f"fitting {measurements[0].name}"
        results = pool.map(fit, measurements, desc="calibrate", unit="file")
        for k, (m, (json_path, png_path), (result, dt)) in enumerate(
                zip(measurements, paths, results, strict=True)):
            t0 = time.perf_counter()
            record.stage = f"writing {m.name}"
            write_json(result.to_json(m, extrapolate=args.extrapolate), json_path)
            outputs.done(json_path)
            for line in far_extrapolation(m, result, args.extrapolate, grid):
                warn(f"{m.path}: {line}")
            if png_path is not None:
                write_report(m, result, png_path, args.extrapolate)
                outputs.done(png_path)
            elif json_path.with_suffix(".png").exists():
                mismatched.append(f"{json_path.with_suffix('.png')} is an earlier run's report "
                                  f"(--no-report): it does not show this fit of {m.name}; "
                                  "left as it is")
            rows.append((m.name, result, dt + time.perf_counter() - t0))
            if result.rmse > fit_km.NOISE_SIGMAS * noise:
                mismatched.append(
                    f"{m.path}: the fit's RMS error {result.rmse:.2g} is "
                    f"{result.rmse / noise:.1f}x --noise {noise:g}: S, K do not reproduce the "
                    "readings (columns or thicknesses mislabelled, or readings noisier than "
                    "--noise: see the report)")
            if k + 1 < len(measurements):
                record.stage = f"fitting {measurements[k + 1].name}"
    for line in mismatched:
        warn(line)
    wide = max([24, *(len(name) for name, _, _ in rows)])  # long names kept the columns
    figures = [_coverage_cells(r) for _, r, _ in rows]
    cr = max([8, *(len(f[0]) for f in figures)])
    print(f"{'material':<{wide}} {'bands':>5} {'identifiable':>12} {'rmse':>9} {'steps':>5} "
          f"{'CR':>{cr}} {'hide 98%':>10} {'ΔE00 b/w':>{cr}} {'time s':>7}")
    for (name, r, dt), (c, x98, de) in zip(rows, figures, strict=True):
        flag = "" if r.converged else "  (not converged: see report)"
        print(f"{name:<{wide}} {len(r.wavelength_nm):>5} {int(r.identifiable.sum()):>12} "
              f"{r.rmse:>9.2e} {r.steps:>5} {c:>{cr}} {x98:>10} {de:>{cr}} {dt:>7.2f}{flag}")
    print("CR: contrast ratio Y over black / Y over white of each film as measured, hide 98%: "
          "the thickness where it is 0.98, ΔE00 b/w: CIEDE2000 over black vs white (ASTM "
          "D2805's black 0 and white 0.80 under the film; D65, 10°; x film: in multiples of a "
          "film of unknown thickness)")
    print_written(outputs)
    return 0


def _coverage_cells(r) -> tuple[str, str, str]:
    """The table's contrast ratios and ΔE2000 (one per film, '/' between) and the hiding
    thickness, as text."""
    cov = r.coverage
    c = "/".join(f"{f['contrast_ratio']:.3f}" for f in cov["films"])
    de = "/".join(f"{f['delta_E2000']:.1f}" for f in cov["films"])
    if r.thickness_known:
        x = cov["hiding_98_mm"]
        x98 = "-" if x is None else f"{x:.3g} mm"
    else:
        x = cov["hiding_98_films"]
        x98 = "-" if x is None else f"{x:.3g} x film"
    return c, x98, de


def _read_all(args, outputs: Outputs, noise: float) -> tuple[list, list]:
    """Every file read and checked, and its outputs planned, before anything is fitted: a
    bad file anywhere means nothing is written. `(measurements, [(json, png or None)])`."""
    from jaxskin.fitting import km as fit_km
    from jaxskin.fitting.measurements import read_measurement

    measurements, paths = [], []
    for f in args.files:
        m = read_measurement(f, thickness_mm=args.thickness, percent=args.percent,
                             ignore=args.ignore, white_reflectance=args.white_reflectance)
        check_name(m.name, f, key="name")
        json_path = outputs.plan(f"{m.name}.json", f)
        png_path = None if args.no_report else outputs.plan(f"{m.name}.png", f)
        fit_km.check_saunderson(m, args.saunderson)
        if not fit_km.identifiable(m, noise).any():
            fit_km.fit(m, noise=noise)  # raises the InputError that explains why
        measurements.append(m)
        paths.append((json_path, png_path))
    return measurements, paths


def _warn_about_the_readings(args, measurements, grid, noise: float) -> None:
    """Each file's notes, and warnings: wavelengths the renderer's grid needs but the file
    does not cover, gaps, suspect column labels, a `--thickness` no column uses."""
    from jaxskin.fitting import km as fit_km
    from jaxskin.fitting.measurements import takes_thickness
    from jaxskin.formats import wavelength_gaps

    for m in measurements:
        for line in m.notes:
            note(line)
        wl = m.wavelength_nm
        if args.extrapolate is None and (wl[0] > grid[0] or wl[-1] < grid[-1]):
            warn(f"{m.path}: covers {wl[0]:g}-{wl[-1]:g} nm, not the "
                 f"renderer's {grid[0]:g}-{grid[-1]:g} nm: the material will be refused at "
                 "render time; pass --extrapolate hold|linear to allow it")
        share = (min(wl[-1], grid[-1]) - max(wl[0], grid[0])) / (grid[-1] - grid[0])
        if args.extrapolate is not None and share < 0.5:
            part = f"{share:.0%} of" if share > 0 else "none of"
            warn(f"{m.path}: covers {wl[0]:g}-{wl[-1]:g} nm, {part} the "
                 f"renderer's {grid[0]:g}-{grid[-1]:g} nm: --extrapolate {args.extrapolate} "
                 "makes up the rest")
        for line in wavelength_gaps(wl):
            warn(f"{m.path}: {line}")
        for line in fit_km.suspect_labels(m, noise):
            warn(line)
        for line in _card_bands(m, noise):
            warn(line)
    if args.thickness is not None and not any(takes_thickness(c) for m in measurements
                                              for c in m.columns):
        warn(f"--thickness {args.thickness:g} was ignored: no file has a bare "
             "R (or E) column; each gives its thicknesses in its column names (R_<X>mm)")


def _card_bands(m, noise: float) -> list[str]:
    """A contrast card's inconsistent bands (a film brighter over black than over white), in
    one line naming them; none for another layout or a consistent card."""
    from jaxskin.fitting import cards
    from jaxskin.fitting import km as fit_km

    if not m.is_card:
        return []
    wl = m.wavelength_nm[cards.band_status(m, noise, fit_km.MIN_RUN) == "inconsistent"]
    if not wl.size:
        return []
    shown = ", ".join(f"{w:g}" for w in wl[:8]) + (", ..." if wl.size > 8 else "")
    return [f"{m.path}: {wl.size} band(s) where a film is brighter over the card's black part "
            f"than over its white part by over 3√2 x --noise {noise:g} ({shown} nm), which no "
            "film does: fitted as opaque there (R∞ from both readings), marked "
            "'inconsistent' in the JSON's band_status"]
