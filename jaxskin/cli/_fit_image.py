"""`jaxskin fit-image`: scene values and texture-space maps fitted to a target image
(`jaxskin.fitting.image`)."""

from __future__ import annotations

from .. import cluster
from ._options import number, overrides
from ._process import Run

__all__ = ["add_parser", "run"]


def add_parser(sub) -> None:
    """The `jaxskin fit-image` subcommand and its options."""
    f = sub.add_parser(
        "fit-image",
        help="fit scene values and texture-space maps to a target image (inverse rendering)",
        description="Fit the named values of a scene to TARGET, an image seen from the "
        "scene's camera (same size): scalars (any differentiable key: material.melanin, "
        "light.intensity, layer.NAME.thickness_mm, ...) by Levenberg-Marquardt, and "
        "texture-space maps (layer.NAME.map, skin.melanin_map; biophysical skin: "
        "skin.melanin_fraction_map, skin.haemoglobin_map) with a smoothness prior by a "
        "per-texel Gauss-Newton (Levenberg-Marquardt). The loss is the mean squared "
        "difference of display values over the pixels the "
        "mesh covers fully (and the mask's, if any). Writes DIR/<name>.toml (the scene with "
        "the fitted values; jaxskin render turns it into the fitted image), DIR/<name>_<map "
        "key>.png (each fitted map, 16-bit grey, loaded by that scene) and DIR/<name>_fit.png "
        "(target, fit, residual, loss, maps). Warns when two fitted keys trade off against "
        "each other (exposure and intensity, albedo and intensity).",
    )
    f.add_argument("scene", metavar="SCENE", help="built-in name or TOML file: the start")
    f.add_argument("target", metavar="TARGET.png", help="the image to fit")
    f.add_argument("--fit", required=True, metavar="KEY[,KEY...]", help="the keys to fit")
    f.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder")
    f.add_argument("--mask", metavar="M.png", help="weights in [0, 1] per pixel (grey; 0: "
                   "ignore), the target's size")
    f.add_argument("--steps", type=number(int, 1, 100000), default=100, metavar="N",
                   help="at most N optimiser steps, 1-100000 (100)")
    f.add_argument("--smooth", type=number(lo=0.0, hi=1e6), default=1e-6, metavar="W",
                   help="weight of the maps' total-variation prior (1e-6; 1e-5 pulled the "
                   "makeup maps flat at noise 0.01)")
    cluster.add_option(f, "fit (the whole fit: one task, no per-step progress)")
    f.add_argument("--solver", choices=("auto", "gn", "adam"), default="auto",
                   help="maps: gn, the per-texel Gauss-Newton (auto's choice: fewer steps, "
                   "fits to the noise), or adam (cheaper steps); scalars alone: "
                   "Levenberg-Marquardt either way")
    overrides(f, "override a scene value (the fit's start), as for render")


def run(args, record: Run) -> int:
    """Fit, then write the fitted scene, its maps and the report."""
    from ..fitting import image

    return image.run_command(args, record)
