"""`jaxskin fit-image`'s body (`run_command`): reads the inputs, fits, writes the outputs."""

from __future__ import annotations

import functools
import warnings
from pathlib import Path

import numpy as np

from jaxskin import cluster, render
from jaxskin.io import InputError, atomic_write

from ._keys import fit_keys, schema
from ._loss import ABOVE_NOISE, noise_sigma, weights
from ._report import write_report
from ._solve import fit, map_image


def _jpeg_note(path) -> str | None:
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


def run_command(args, run) -> int:
    """`jaxskin fit-image` (the CLI's body): check everything, fit, write DIR/<name>.toml,
    the maps as 16-bit PNGs and DIR/<name>_fit.png. `run`: the CLI's record of what is
    written."""
    from tqdm import tqdm

    from jaxskin import cli, maps
    from jaxskin.checks import check_scene, reading
    from jaxskin.outputs import Outputs, check_name
    from jaxskin.scene import load_scene
    from jaxskin.scene_writer import scene_toml

    outputs = Outputs(args.output)
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
    config = scene.config
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
    outputs.inputs += [Path(p) for p in check_scene(scene, 1, args.overrides)]
    outputs.inputs += [Path(p) for p in (args.target, args.mask) if p is not None]
    name = check_name(scene.name, scene.source)
    toml_path = outputs.plan(f"{name}.toml", "the fitted scene")
    report_path = outputs.plan(f"{name}_fit.png", "the report")
    map_paths = {fk.key: outputs.plan(f"{name}_{fk.key}.png", fk.key)
                 for fk in keys if fk.kind == "map"}
    brdf_path = (outputs.plan(f"{name}_brdf.json", "the fitted lobes")
                 if any(fk.kind == "lafortune" for fk in keys) else None)
    params = scene.params
    w = weights(config, params, target_alpha, mask)
    if w.sum() <= 0:
        opaque = target_alpha is None or bool(np.any(np.asarray(target_alpha) > 0))
        raise InputError("no pixel to fit: " + (
            "the target's alpha is 0 everywhere (a fully transparent image)" if not opaque else
            "the mesh covers no pixel fully" + (" inside the mask" if mask is not None else "")
            + (" where the target's alpha is above 0" if target_alpha is not None else "")),
            args.mask or args.target)
    fitted = np.asarray(target)[w > 0]
    if np.all(fitted.max(axis=-1) == fitted.min(axis=-1)):
        warnings.warn(f"{args.target}: the target is greyscale (R = G = B at every fitted "
                      "pixel) and the render is in colour: the fit can only match its "
                      "brightness, so skin and cosmetic colour keys come out wrong; fit a "
                      "colour photograph", stacklevel=1)
    lossy = _jpeg_note(args.target)
    if lossy:
        warnings.warn(f"{args.target}: {lossy}: its colours are shifted at the scale of a few "
                      "pixels, which biases the colour keys (blood came out 0.16 for a true "
                      "0.3 at quality 95, 4:2:0) while the fit looks good; give a PNG or TIFF",
                      stacklevel=1)
    run.outputs.append(outputs)
    run.stage = "fitting"
    print(f"fitting {', '.join(k.key for k in keys)} to {args.target} "
          f"({width}x{height}, {int((w > 0).sum())} pixels)", flush=True)
    with cluster.pool(args.cluster) as pool:
        if pool.client is None:  # here: a progress bar over the steps, with the loss
            with tqdm(total=args.steps, desc="fit-image", unit="step", disable=None) as bar:
                def progress(loss):
                    bar.set_postfix(loss=f"{loss:.3e}", refresh=False)
                    bar.update(1)

                result = fit(config, params, target, w, keys, steps=args.steps,
                             smooth=args.smooth, progress=progress, solver=solver)
        else:  # the fit is one unit of work: one task on a worker (a GPU one, say)
            unit = functools.partial(fit, config, params, target, w, keys, steps=args.steps,
                                     smooth=args.smooth, solver=solver)
            (result, _), = pool.map(lambda _: unit(), [None], desc="fit-image", unit="fit")
    run.stage = "writing"
    tmask = np.asarray(render.prepare(config).arrays["mask"])
    values = dict(result.values)
    if "light.direction" in values:  # free while fitting (the renderer normalises it)
        d = np.asarray(values["light.direction"], np.float64)
        values["light.direction"] = d / np.linalg.norm(d)
    if brdf_path is not None:
        from jaxskin.formats import write_lafortune

        write_lafortune(values.pop("material.lafortune"), brdf_path,
                        fit={"source": Path(args.target).name, "rms": result.rms})
        outputs.done(brdf_path)
        values["material.brdf"] = brdf_path.name
    images, shown = {}, {}
    for fk in keys:
        if fk.kind != "map":
            continue
        grey, scalar = map_image(result, fk, tmask)
        hi = schema(fk.scalar).hi
        if scalar > hi:
            warnings.warn(f"{fk.key}: the fitted map's largest value {scalar:g} is beyond "
                          f"{fk.scalar}'s range (≤ {hi:g}); written as {hi:g}", stacklevel=1)
            grey, scalar = grey * scalar / hi, hi
        values[fk.scalar] = scalar
        maps.write_grey16(grey, map_paths[fk.key])
        outputs.done(map_paths[fk.key])
        images[fk.key] = map_paths[fk.key].name
        shown[fk.key] = (grey * scalar, tmask, "mm" if fk.scalar.endswith("_mm") else
                         fk.scalar)
    comment = (f"Fitted by jaxskin fit-image to {args.target} ({result.solver}, "
               f"{result.steps} steps, RMS {result.rms:.4g})\nfrom {scene.source}; fitted: "
               + ", ".join(k.key for k in keys))
    with atomic_write(toml_path, "w") as fh:
        fh.write(scene_toml(scene, values, images, comment))
    outputs.done(toml_path)
    write_report(result, target, w, shown, report_path,
                 f"{scene.name}: fit-image {', '.join(k.key for k in keys)}")
    outputs.done(report_path)
    print(f"{'key':<28} {'start':>12} {'fitted':>12}")
    for fk in keys:
        if fk.kind == "lafortune":
            print(f"{fk.key:<28} {'(lobes)':>12} {brdf_path.name:>12}")
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
        warnings.warn(f"the fit ends at RMS {result.rms:.3g}, {result.rms / floor:.0f}x {noise}"
                      f"{limit}: the fitted keys do not explain the image; fit more keys, "
                      "start closer (-D KEY=VALUE) or allow more --steps, and see the "
                      "residual in the report", stacklevel=1)
    cli._print_written(outputs)
    return 0


def _fmt(v) -> str:
    a = np.asarray(v, np.float64)
    return f"{float(a):.4g}" if a.ndim == 0 else "[" + ", ".join(f"{x:.3g}" for x in a) + "]"
