"""`jaxskin fit-image`: scene values and texture-space maps fitted to a target image
(`jaxskin.fitting.image`); writes the fitted scene, its maps and a report."""

from __future__ import annotations

import functools
from pathlib import Path

from .. import cluster
from ..io import InputError
from ..outputs import Outputs
from ._options import number, overrides
from ._process import Run, print_written
from ._terminal import warn

__all__ = ["add_parser", "jpeg_note", "run"]


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
    """Check everything, fit, write DIR/<name>.toml, the maps as 16-bit PNGs and
    DIR/<name>_fit.png, and print the summary."""
    outputs = Outputs(args.output)
    scene, keys, solver = _scene_and_keys(args)
    target, target_alpha, mask = _target_and_mask(args, scene.config)
    paths = _plan(args, outputs, scene, keys)
    w = _weights(args, scene, target, target_alpha, mask)
    record.outputs.append(outputs)
    record.stage = "fitting"
    config = scene.config
    height, width = config.image_height or config.image, config.image
    print(f"fitting {', '.join(k.key for k in keys)} to {args.target} "
          f"({width}x{height}, {int((w > 0).sum())} pixels)", flush=True)
    result = _fit(args, scene, target, w, keys, solver)
    record.stage = "writing"
    values = _write(args, outputs, paths, scene, keys, result, target, w)
    _summary(args, scene.params, keys, values, paths, result, target, w)
    print_written(outputs)
    return 0


def _scene_and_keys(args):
    """The scene (with `-D`), the keys to fit, and the solver they allow."""
    from ..checks import reading
    from ..fitting.image import fit_keys
    from ..scene import load_scene

    with reading(args.scene):
        scene = load_scene(args.scene, args.overrides, flag="-D")
    keys = fit_keys(scene, args.fit)
    has_maps = any(fk.kind == "map" for fk in keys)
    solver = getattr(args, "solver", "auto")
    if solver == "gn" and (not has_maps or any(fk.kind == "lafortune" for fk in keys)):
        raise InputError("the Gauss-Newton solver is for maps (and not with "
                         "material.lafortune); use --solver auto", "--solver")
    if not has_maps:
        solver = "auto"
    return scene, keys, solver


def _target_and_mask(args, config):
    """The target image, its alpha (or None) and the mask's grey weights (or None), each
    checked against the camera's size."""
    from .. import maps

    height, width = config.image_height or config.image, config.image
    target, target_alpha = maps.read_image(args.target, "image")
    if target.shape[:2] != (height, width):
        raise InputError(f"the target is {target.shape[1]}x{target.shape[0]} pixels, the "
                         f"scene's camera {width}x{height} (camera.size, camera.height; set "
                         "them with -D)", args.target)
    mask = None
    if args.mask is not None:
        rgb, _ = maps.read_image(args.mask, "image")
        if rgb.shape[:2] != (height, width):
            raise InputError(f"the mask is {rgb.shape[1]}x{rgb.shape[0]} pixels, the target "
                             f"{width}x{height}", args.mask)
        mask = rgb.mean(axis=-1)
    return target, target_alpha, mask


def _plan(args, outputs: Outputs, scene, keys) -> dict:
    """The scene's inputs checked and recorded, and every output path planned: `toml`,
    `report`, `maps` (fitted key → path), `brdf` (or None)."""
    from ..checks import check_scene
    from ..outputs import check_name

    outputs.inputs += [Path(p) for p in check_scene(scene, 1, args.overrides)]
    outputs.inputs += [Path(p) for p in (args.target, args.mask) if p is not None]
    name = check_name(scene.name, scene.source)
    return {
        "name": name,
        "toml": outputs.plan(f"{name}.toml", "the fitted scene"),
        "report": outputs.plan(f"{name}_fit.png", "the report"),
        "maps": {fk.key: outputs.plan(f"{name}_{fk.key}.png", fk.key)
                 for fk in keys if fk.kind == "map"},
        "brdf": (outputs.plan(f"{name}_brdf.json", "the fitted lobes")
                 if any(fk.kind == "lafortune" for fk in keys) else None),
    }


def _weights(args, scene, target, target_alpha, mask):
    """Each pixel's weight in the loss; `InputError` when none is left; warnings for a
    target that cannot pin colours down (greyscale, JPEG)."""
    import numpy as np

    from ..fitting.image import weights

    w = weights(scene.config, scene.params, target_alpha, mask)
    if w.sum() <= 0:
        opaque = target_alpha is None or bool(np.any(np.asarray(target_alpha) > 0))
        raise InputError("no pixel to fit: " + (
            "the target's alpha is 0 everywhere (a fully transparent image)" if not opaque else
            "the mesh covers no pixel fully" + (" inside the mask" if mask is not None else "")
            + (" where the target's alpha is above 0" if target_alpha is not None else "")),
            args.mask or args.target)
    fitted = np.asarray(target)[w > 0]
    if np.all(fitted.max(axis=-1) == fitted.min(axis=-1)):
        warn(f"{args.target}: the target is greyscale (R = G = B at every fitted pixel) and "
             "the render is in colour: the fit can only match its brightness, so skin and "
             "cosmetic colour keys come out wrong; fit a colour photograph")
    lossy = jpeg_note(args.target)
    if lossy:
        warn(f"{args.target}: {lossy}: its colours are shifted at the scale of a few pixels, "
             "which biases the colour keys (blood came out 0.16 for a true 0.3 at quality "
             "95, 4:2:0) while the fit looks good; give a PNG or TIFF")
    return w


def _fit(args, scene, target, w, keys, solver):
    """The fit, here with a progress bar over the steps (and the loss), or on the cluster
    as one task."""
    from tqdm import tqdm

    from ..fitting.image import fit

    config, params = scene.config, scene.params
    with cluster.pool(args.cluster) as pool:
        if pool.client is None:
            with tqdm(total=args.steps, desc="fit-image", unit="step", disable=None) as bar:
                def progress(loss):
                    bar.set_postfix(loss=f"{loss:.3e}", refresh=False)
                    bar.update(1)

                return fit(config, params, target, w, keys, steps=args.steps,
                           smooth=args.smooth, progress=progress, solver=solver)
        # the fit is one unit of work: one task on a worker (a GPU one, say)
        unit = functools.partial(fit, config, params, target, w, keys, steps=args.steps,
                                 smooth=args.smooth, solver=solver)
        (result, _), = pool.map(lambda _: unit(), [None], desc="fit-image", unit="fit")
        return result


def _write(args, outputs: Outputs, paths: dict, scene, keys, result, target, w) -> dict:
    """Write the fitted lobes, each fitted map (16-bit grey, its largest value the scene's
    scalar), the fitted scene and the report; the scene's fitted values."""
    import numpy as np

    from .. import maps, render
    from ..fitting.image import map_image, schema, write_report
    from ..io import atomic_write
    from ..scene import scene_toml

    tmask = np.asarray(render.prepare(scene.config).arrays["mask"])
    values = dict(result.values)
    if "light.direction" in values:  # free while fitting (the renderer normalises it)
        d = np.asarray(values["light.direction"], np.float64)
        values["light.direction"] = d / np.linalg.norm(d)
    if paths["brdf"] is not None:
        from ..formats import write_lafortune

        write_lafortune(values.pop("material.lafortune"), paths["brdf"],
                        fit={"source": Path(args.target).name, "rms": result.rms})
        outputs.done(paths["brdf"])
        values["material.brdf"] = paths["brdf"].name
    images, shown = {}, {}
    for fk in keys:
        if fk.kind != "map":
            continue
        grey, scalar = map_image(result, fk, tmask)
        hi = schema(fk.scalar).hi
        if scalar > hi:
            warn(f"{fk.key}: the fitted map's largest value {scalar:g} is beyond "
                 f"{fk.scalar}'s range (≤ {hi:g}); written as {hi:g}")
            grey, scalar = grey * scalar / hi, hi
        values[fk.scalar] = scalar
        maps.write_grey16(grey, paths["maps"][fk.key])
        outputs.done(paths["maps"][fk.key])
        images[fk.key] = paths["maps"][fk.key].name
        shown[fk.key] = (grey * scalar, tmask, "mm" if fk.scalar.endswith("_mm") else
                         fk.scalar)
    comment = (f"Fitted by jaxskin fit-image to {args.target} ({result.solver}, "
               f"{result.steps} steps, RMS {result.rms:.4g})\nfrom {scene.source}; fitted: "
               + ", ".join(k.key for k in keys))
    with atomic_write(paths["toml"], "w") as fh:
        fh.write(scene_toml(scene, values, images, comment))
    outputs.done(paths["toml"])
    write_report(result, target, w, shown, paths["report"],
                 f"{scene.name}: fit-image {', '.join(k.key for k in keys)}")
    outputs.done(paths["report"])
    return values


def _summary(args, params, keys, values, paths, result, target, w) -> None:
    """The table of start and fitted values, the RMS against the target's noise, and a
    warning when the fit ends well above that noise."""
    from ..fitting.image import ABOVE_NOISE, noise_sigma

    print(f"{'key':<28} {'start':>12} {'fitted':>12}")
    for fk in keys:
        if fk.kind == "lafortune":
            print(f"{fk.key:<28} {'(lobes)':>12} {paths['brdf'].name:>12}")
        elif fk.kind != "map":
            print(f"{fk.key:<28} {_fmt(params[fk.key]):>12} {_fmt(values[fk.key]):>12}")
        else:
            print(f"{fk.key:<28} {'(map)':>12} {'× ' + _fmt(values[fk.scalar]):>12}")
    sigma = noise_sigma(target, w)
    print(f"RMS difference {result.rms:.4g} (display values) after {result.steps} steps "
          f"({result.seconds:.1f} s)"
          + ("" if sigma is None else f"; the target's noise estimate {sigma:.2g}"))
    floor = None if sigma is None else max(sigma, 0.5 / 255)  # 8-bit rounding at least
    if floor is not None and result.rms > ABOVE_NOISE * floor:
        limit = (f"; it stopped at the --steps limit ({args.steps})"
                 if result.steps >= args.steps else "")
        noise = (f"the target's noise estimate ({sigma:.2g}, from its pixel-to-pixel "
                 "variation, texture included)" if sigma >= floor else
                 f"half an 8-bit step ({floor:.2g}; the target varies less than that from "
                 "pixel to pixel, a flat colour?)")
        warn(f"the fit ends at RMS {result.rms:.3g}, {result.rms / floor:.0f}x {noise}"
             f"{limit}: the fitted keys do not explain the image; fit more keys, start "
             "closer (-D KEY=VALUE) or allow more --steps, and see the residual in the report")


def jpeg_note(path) -> str | None:
    """"a JPEG (lossy, chroma subsampled 4:2:0)" and the like for a JPEG file, else None."""
    try:
        with open(path, "rb") as f:
            if f.read(3) != b"\xff\xd8\xff":
                return None
        from PIL import Image, JpegImagePlugin

        with Image.open(path) as im:
            sampling = JpegImagePlugin.get_sampling(im)
    except (OSError, ValueError, ImportError):
        return "a JPEG (lossy)"
    kind = {0: "4:4:4", 1: "4:2:2", 2: "4:2:0"}.get(sampling)
    return "a JPEG (lossy" + (f", chroma subsampled {kind})" if sampling in (1, 2) else ")")


def _fmt(v) -> str:
    """A fitted value in the summary table: 4 digits, a vector's each 3."""
    import numpy as np

    a = np.asarray(v, np.float64)
    return f"{float(a):.4g}" if a.ndim == 0 else "[" + ", ".join(f"{x:.3g}" for x in a) + "]"
