"""`jaxskin fit-skin`: the biophysical skin model fitted to each of a table's reflectance
spectra (`jaxskin.fitting.skin`)."""

from __future__ import annotations

import math
import time
from pathlib import Path

from .. import cluster
from ..io import InputError
from ..outputs import Outputs, slug
from ._options import no_report, number, seed
from ._process import Run, print_written
from ._terminal import note, warn

__all__ = ["add_parser", "covered", "fixed_values", "run"]


def add_parser(sub) -> None:
    """The `jaxskin fit-skin` subcommand and its options."""
    k = sub.add_parser(
        "fit-skin",
        help="fit the biophysical skin model to measured reflectance spectra",
        description="Fit melanin (fraction, eumelanin share), haemoglobin (fraction, "
        "oxygenation), epidermis thickness and scattering of the biophysical skin model "
        "(material.model = \"biophysical\") to each spectrum of a CSV: a wide table "
        "(wavelength_nm, then one column per spectrum, 0-1) or the NIST skin file's layout "
        "(each subject's Average). Any sampling (1-10 nm steps are usual); fits the "
        "readings in 400-700 nm, each weighted by the stretch of spectrum it stands for "
        "(dE2000 compares all readings in 380-780 nm). "
        "A spectrum must cover at least 400-700 nm: one that covers less (an empty cell is "
        "a missing reading) is named and skipped. Writes DIR/<SPECTRA>_fit.csv (name, "
        "parameters, RMS reflectance error, dE2000 under D65 between measured and fitted "
        "spectra, the --specular mode) and DIR/<SPECTRA>_fit.png (a sample of fits, "
        "histograms), named by the CSV's stem.",
    )
    k.add_argument("file", metavar="SPECTRA.csv", help="reflectance spectra")
    k.add_argument("-o", "--output", required=True, metavar="DIR",
                   help="folder for <SPECTRA>_fit.csv and .png (created if missing)")
    k.add_argument("--starts", type=number(int, 1, 256), default=4, metavar="S",
                   help="starts per spectrum, 1-256: the default skin, then random (4)")
    seed(k)
    k.add_argument("--fix", action="append", default=[], metavar="NAME=VALUE",
                   help="hold a parameter at a value, e.g. --fix epidermis_mm=0.06 "
                   "(repeatable)")
    k.add_argument("--specular", choices=("included", "excluded"), default="excluded",
                   help="the instrument's mode: a d/8 sphere reports the specular component "
                   "included (SCI) or excluded (SCE); with 'included' the model adds the "
                   "skin surface's own reflection (k1 = 0.028 at every wavelength) "
                   "(default: excluded)")
    k.add_argument("--percent", action="store_true",
                   help="reflectance is in percent (0-100) instead of 0-1 (without it, spectra "
                   "whose median is above 1.5 are read as percent, with a note)")
    no_report(k, "CSV")
    cluster.add_option(k, "chunk of 10 spectra")


def run(args, record: Run) -> int:
    """Read the spectra, fit each, write the CSV and the report."""
    import numpy as np
    from tqdm import tqdm

    from ..fitting import skin
    from ..fitting.measurements import THIN_COLUMN
    from ..formats import read_spectra, wavelength_gaps

    outputs = Outputs(args.output, [args.file])
    fixed = fixed_values(args.fix)
    notes = []
    names, wavelengths, R = read_spectra(args.file, percent=args.percent or None, notes=notes)
    if any(THIN_COLUMN.match(n) for n in names) and {"R_inf", "R_g"} & set(names):
        raise InputError("a cosmetic's measurement (columns R_<X>mm, R_inf, R_g), not skin "
                         f"spectra: calibrate it with 'jaxskin calibrate {args.file} -o DIR'",
                         args.file)
    names, R, skipped = covered(names, wavelengths, R, args.file)
    stem = f"{slug(Path(args.file).stem)}_fit"  # by the input: two fits in one folder
    csv_path = outputs.plan(f"{stem}.csv", "the fit")
    png_path = None if args.no_report else outputs.plan(f"{stem}.png", "the report")
    record.outputs.append(outputs)
    for line in notes:
        note(line)
    for line in skipped:
        warn(line)
    for line in wavelength_gaps(wavelengths):
        warn(f"{args.file}: {line}")
    specular = args.specular == "included"
    record.stage = f"fitting {len(names)} spectra"
    t0 = time.perf_counter()
    if args.cluster:
        with cluster.pool(args.cluster) as pool:
            result = skin.fit(names, wavelengths, R, starts=args.starts, seed=args.seed,
                              fixed=fixed, path=args.file, specular=specular,
                              map_units=pool.mapper(desc="fit-skin", unit="chunk"))
    else:
        with tqdm(total=len(names), desc="fit-skin", unit="spectrum", disable=None) as bar:
            result = skin.fit(names, wavelengths, R, starts=args.starts, seed=args.seed,
                              fixed=fixed, progress=bar.update, path=args.file,
                              specular=specular)
    seconds = time.perf_counter() - t0
    skin.write_csv(result, csv_path)
    outputs.done(csv_path)
    if png_path is not None:
        record.stage = "writing the report"
        skin.write_report(result, png_path)
        outputs.done(png_path)
    de, rms = result.dE2000, result.rms
    print(f"{len(names)} spectra, specular {args.specular}, {args.starts} starts each, "
          f"{seconds:.1f} s: ΔE2000 median "
          f"{np.median(de):.2f}, max {de.max():.2f} ({result.names[int(np.argmax(de))]}); RMS "
          f"reflectance error median {np.median(rms):.4f}, max {rms.max():.4f}")
    for line in skin.fit_warnings(result, fixed):
        warn(line)
    print_written(outputs)
    return 0


def covered(names, wavelengths, R, path):
    """`(names, R, lines)`: the spectra that cover `skin.NEEDED` (400-700 nm) with readings,
    and one warning line naming those that do not (they are skipped); `InputError` when
    none does."""
    import numpy as np

    from ..fitting import skin

    lo, hi = skin.NEEDED
    span = skin.coverage(wavelengths, R)
    ok = (span[:, 0] <= lo) & (span[:, 1] >= hi)
    if not ok.any():
        what = (f"the spectra cover {wavelengths[0]:g}-{wavelengths[-1]:g} nm"
                if np.isfinite(R).all() else "no spectrum covers it with readings")
        raise InputError(f"{what}; the fit needs at least {lo:g}-{hi:g} nm", path)
    if ok.all():
        return list(names), R, []
    short = [f"{n} ({_span(s)})" for n, s, k in zip(names, span, ok, strict=True) if not k]
    more = f" and {len(short) - 5} more" if len(short) > 5 else ""
    line = (f"{path}: {len(short)} of {len(names)} spectra skipped, not covering "
            f"{lo:g}-{hi:g} nm: {', '.join(short[:5])}{more}")
    return [n for n, k in zip(names, ok, strict=True) if k], R[ok], [line]


def _span(span) -> str:
    return "no readings" if not span[0] == span[0] else f"{span[0]:g}-{span[1]:g} nm"


def fixed_values(items) -> dict[str, float]:
    """`--fix name=value` items, checked against `biophysical.RANGES`: `{name: value}`."""
    from .. import biophysical as bp

    out = {}
    for item in items:
        name, sep, text = (s.strip() for s in item.partition("="))
        if not sep or name not in bp.RANGES:
            raise InputError(f"--fix expects name=value with a name among {', '.join(bp.PARAMS)}"
                             f", got {item!r}")
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        lo, hi = bp.RANGES[name]
        if not (math.isfinite(value) and lo <= value <= hi):
            raise InputError(f"--fix {name}: expected a number in [{lo:g}, {hi:g}], got {text!r}")
        if name in out and out[name] != value:  # not the last one taken silently
            raise InputError(f"--fix {name} given twice ({out[name]:g} and {value:g}); give it "
                             "once")
        out[name] = value
    if len(out) == len(bp.PARAMS):
        raise InputError("--fix: every parameter is fixed; nothing is left to fit")
    return out
