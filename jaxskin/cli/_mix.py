"""`jaxskin mix`: a material JSON of a mixture of calibrated materials by the two-constant
Kubelka–Munk rule (`jaxskin.mixture`)."""

from __future__ import annotations

import math

from ..io import InputError
from ..outputs import Outputs, check_name
from ._process import Run, print_written
from ._terminal import note, warn

__all__ = ["SUM_TOLERANCE", "add_density", "add_parser", "densities", "mixture_json",
           "parse_component", "run"]

SUM_TOLERANCE = 1e-3  # concentrations must sum to 1 within this (a formula's rounding)


def add_parser(sub) -> None:
    """The `jaxskin mix` subcommand and its options."""
    c = sub.add_parser(
        "mix",
        help="mix calibrated materials into a new one (two-constant Kubelka-Munk)",
        description="Mix calibrated materials (jaxskin calibrate's JSON, or a shipped "
        "material's name) by the two-constant Kubelka-Munk rule: the mixture's S and K per mm "
        "are the concentration-weighted sums of its components'. Concentrations are VOLUME "
        "fractions (S, K per mm add per unit volume), each >= 0, summing to 1 (within 0.001: "
        "a rounded formula is scaled to 1, with a note); with --density for every component "
        "they are weight fractions w_i instead, converted to volume fractions "
        "c_i = (w_i/rho_i) / sum_j (w_j/rho_j). "
        "Components on different wavelength grids are resampled (linearly in log S, log K) "
        "onto the range they all cover, with a note; that range must include 400-700 nm. "
        "Writes OUTDIR/<name>.json, a material the renderer reads at once "
        "(-D layer.<layer>.material=OUTDIR/<name>.json).",
    )
    c.add_argument("components", nargs="+", metavar="MATERIAL:C",
                   help="a material file (or shipped name) and its volume fraction, e.g. "
                   "base.json:0.75")
    c.add_argument("-o", "--output", required=True, metavar="OUTDIR",
                   help="folder for <name>.json (created if missing)")
    c.add_argument("--name", metavar="NAME",
                   help="the mixture's material name and file name (default: mix_ and the "
                   "components' names joined by _)")
    add_density(c, "the concentrations are WEIGHT fractions, converted to volume fractions "
                "with these densities")


def add_density(p, what: str) -> None:
    """`--density NAME=RHO` (repeatable, into `args.density`)."""
    p.add_argument("--density", action="append", default=[], metavar="NAME=RHO",
                   help=f"a component's density (g/cm3, or any one unit for all), by its "
                   f"material name; repeat it for every component, and {what}")


def densities(items, names) -> dict[str, float] | None:
    """`--density NAME=RHO` items → `{name: rho}` for every one of `names`, or None when
    none is given; `InputError` for a bad item, an unknown or repeated name, or a component
    left without one."""
    if not items:
        return None
    out = {}
    for item in items:
        name, sep, text = (s.strip() for s in item.partition("="))
        try:
            rho = float(text)
        except ValueError:
            rho = math.nan
        if not sep or name not in names or not (math.isfinite(rho) and rho > 0):
            raise InputError(f"--density expects NAME=RHO with RHO > 0 and NAME a component's "
                             f"material name ({', '.join(names)}), got {item!r}")
        if name in out:
            raise InputError(f"--density {name} given twice; give it once")
        out[name] = rho
    missing = [n for n in names if n not in out]
    if missing:
        raise InputError(f"--density: every component needs one (weight fractions need all "
                         f"the densities); missing {', '.join(missing)}")
    return out


def parse_component(text: str) -> tuple[str, float]:
    """`PATH:C` → `(PATH, C)`; `InputError` unless C is a finite number in [0, 1]. The last
    colon splits, so a path may contain colons."""
    path, sep, value = text.rpartition(":")
    if not sep or not path:
        raise InputError(f"expected MATERIAL:C (a material file and its volume fraction, "
                         f"e.g. base.json:0.75), got {text!r}")
    try:
        c = float(value)
    except ValueError:
        c = math.nan
    if not math.isfinite(c) or c < 0 or c > 1:
        raise InputError(f"the concentration of {path} must be a volume fraction in [0, 1] "
                         f"(e.g. {path}:0.2), got {value!r}")
    return path, c


def run(args, record: Run) -> int:
    """Read and check every component, then write the mixture's material JSON."""
    import jax
    import numpy as np

    from .. import mixture
    from ..cosmetics import material_path
    from ..fitting.match import read_components
    from ..formats import write_json

    parsed = [parse_component(t) for t in args.components]
    total = sum(c for _, c in parsed)
    if abs(total - 1.0) > SUM_TOLERANCE:
        raise InputError(f"the concentrations sum to {total:.6g}; volume fractions of the "
                         f"whole mixture must sum to 1 (within {SUM_TOLERANCE:g})")
    paths = [material_path(p) for p, _ in parsed]
    comps = read_components(paths)
    rho = densities(args.density, comps.names)
    name = args.name or "mix_" + "_".join(comps.names)
    check_name(name, key="--name")
    outputs = Outputs(args.output, paths)
    json_path = outputs.plan(f"{name}.json", "the mixture")
    record.outputs.append(outputs)
    for line in comps.notes:
        note(line)
    c = np.array([c for _, c in parsed])
    if abs(c.sum() - 1.0) > 1e-12:  # a formula's rounding: the shares, scaled to sum to 1
        note(f"the concentrations sum to {c.sum():.6g}: each divided by that sum")
        c = c / c.sum()
    weights = None
    if rho is not None:
        weights = c
        with jax.enable_x64(True):
            c = np.asarray(mixture.volume_fractions(c, np.array([rho[n] for n in comps.names])))
    doc = mixture_json(name, comps, c, weights, rho)
    record.stage = f"writing {json_path.name}"
    write_json(doc, json_path)
    outputs.done(json_path)
    wl = comps.wavelength_nm
    if comps.extrapolate is None and (wl[0] > 380 or wl[-1] < 780):
        warn(f"the mixture covers {wl[0]:g}-{wl[-1]:g} nm, not the renderer's 380-780 nm: "
             f"add \"extrapolate\": \"hold\" to {json_path} to render it")
    print(", ".join(f"{n} {ci:.4f}" for n, ci in zip(comps.names, c, strict=True))
          + f" by volume -> {name}")
    if weights is not None:
        print("(by weight: " + ", ".join(f"{n} {w:.4f}" for n, w in zip(comps.names, weights,
                                                                        strict=True)) + ")")
    print_written(outputs)
    return 0


def mixture_json(name: str, comps, c, weights=None, rho=None) -> dict:
    """The material file of `comps` (`fitting.match.Components`) mixed at volume fractions
    `c (m,)`: the keys `jaxskin calibrate` writes that the renderer reads, and the recipe
    (with the weight fractions and densities it was given in, if any)."""
    import jax
    import numpy as np

    from .. import mixture

    with jax.enable_x64(True):
        S, K = (np.asarray(a) for a in mixture.mix(comps.S, comps.K, np.asarray(c, np.float64)))
    return {
        "name": name,
        "model": "kubelka-munk",
        "wavelength_nm": [float(v) for v in comps.wavelength_nm],
        "S_per_mm": [float(v) for v in S],
        "K_per_mm": [float(v) for v in K],
        **({"extrapolate": comps.extrapolate} if comps.extrapolate else {}),
        "mixture": {
            "rule": "two-constant Kubelka-Munk: S = sum c_i S_i, K = sum c_i K_i",
            "by": "volume fraction",
            "concentrations": {n: float(ci) for n, ci in zip(comps.names, c, strict=True)},
            **({"weight_fractions": {n: float(w) for n, w in zip(comps.names, weights,
                                                                strict=True)},
                "densities": rho} if weights is not None else {}),
            "files": {n: str(p) for n, p in zip(comps.names, comps.paths, strict=True)},
        },
    }
