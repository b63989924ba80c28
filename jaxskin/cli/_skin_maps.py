"""`jaxskin skin-maps`: a photo or albedo texture inverted into the biophysical skin's maps
(`jaxskin.skin_maps`), written as a scene loads them (`jaxskin.skin_texture`)."""

from __future__ import annotations

import time
from pathlib import Path

from ..io import InputError
from ..outputs import Outputs, slug
from ._options import no_report, number
from ._process import Run, print_written
from ._terminal import note

__all__ = ["add_parser", "run"]

HELD = ("eumelanin", "oxygenation", "epidermis_mm", "scattering")  # --fix accepts these


def add_parser(sub) -> None:
    """The `jaxskin skin-maps` subcommand and its options."""
    k = sub.add_parser(
        "skin-maps",
        help="invert a skin texture (sRGB) into biophysical skin maps",
        description="Invert an albedo or photo texture (sRGB, texture space; its colour read "
        "as the skin's diffuse reflectance under D65) texel by texel into the biophysical "
        "skin's maps: melanin fraction, haemoglobin (blood) fraction and a brightness (the "
        "shading and exposure a photo holds). Writes into DIR, for TEXTURE.png: "
        "<stem>_melanin.png, <stem>_haemoglobin.png, <stem>_brightness.png (16-bit grey, "
        "value / its scene scalar), <stem>_skin_mask.png (white where the skin model "
        "explains the colour), <stem>_reproduced.png (the texture made again from the "
        "maps, 8-bit sRGB), <stem>_skin.toml (scene lines that load the maps, and the texture "
        "as the colour of the texels outside the mask) and "
        "<stem>_skin_maps.png (the report).",
    )
    k.add_argument("file", metavar="TEXTURE.png", help="an RGB texture (8 or 16 bits; an "
                   "alpha channel's transparent texels are not skin)")
    k.add_argument("-o", "--output", required=True, metavar="DIR",
                   help="folder for the maps, mask, reproduction, snippet and report "
                   "(created if missing)")
    k.add_argument("--fix", action="append", default=[], metavar="NAME=VALUE",
                   help="the value of a parameter held over the whole texture: "
                   f"{', '.join(HELD)} (default: the model's DEFAULT; repeatable)")
    k.add_argument("--threshold", type=number(float, 0.1, 50.0), default=None, metavar="DE",
                   help="the largest CIEDE2000 between texture and fit at which a texel is "
                   "skin, 0.1-50 (2.0)")
    no_report(k, "maps")


def run(args, record: Run) -> int:
    """Check the texture, invert it, write the files."""
    import numpy as np

    from .. import skin_maps, skin_texture
    from ._fit_skin import fixed_values

    fixed = fixed_values(args.fix)
    bad = sorted(set(fixed) - set(HELD))
    if bad:
        raise InputError(f"--fix {bad[0]}: fitted per texel here; --fix takes "
                         f"{', '.join(HELD)}")
    fixed = skin_maps.Fixed(**fixed)
    outputs = Outputs(args.output, [args.file])
    stem = slug(Path(args.file).stem)
    rgb, alpha, notes = skin_texture.read_texture(args.file)  # checked before any work
    planned = {what: outputs.plan(name, what) for what, name in
               skin_texture.output_names(stem, not args.no_report).items()}
    record.outputs.append(outputs)
    for line in notes:
        note(line)
    record.stage = f"inverting {rgb.shape[1]}x{rgb.shape[0]} texels"
    t0 = time.perf_counter()
    inv = skin_texture.invert_texture(rgb, alpha, fixed, args.threshold)
    seconds = time.perf_counter() - t0
    record.stage = "writing the maps"
    for path in skin_texture.write_all(inv, rgb, outputs.folder, stem, fixed, planned,
                                       not args.no_report, args.file).values():
        outputs.done(path)
    de = inv.de[inv.skin]
    figures = (f"ΔE2000 over them median {np.median(de):.2f}, 95th percentile "
               f"{np.percentile(de, 95):.2f}" if de.size else "none")
    print(f"{rgb.shape[1]}x{rgb.shape[0]} texels in {seconds:.1f} s: skin {inv.skin.mean():.1%}"
          f" of them, {figures}")
    print_written(outputs)
    return 0
