"""`jaxskin render`: scenes to images (PNG, 16-bit PNG or OpenEXR), their texture-space
maps and GLB models, with `-D` overrides and `--sweep`s, here or on a Dask cluster."""

from __future__ import annotations

import time
from pathlib import Path

from .. import batch, cluster
from ..checks import (
    check_scene,
    empty_picture,
    idle_map_keys,
    picture_warnings,
    reading,
    unused_overrides,
)
from ..io import FitError, InputError
from ..outputs import Outputs
from ._names import (
    base_name,
    parse_sweep,
    reads_instead,
    sweep_suffixes,
    sweeps,
    warn_repeated,
)
from ._options import overrides
from ._process import Run, print_written
from ._terminal import warn

__all__ = ["add_parser", "run"]


def add_parser(sub) -> None:
    """The `jaxskin render` subcommand and its options."""
    r = sub.add_parser(
        "render",
        help="render scenes to PNG (and their texture-space maps)",
        description="Render one or more scenes: a built-in name (hand, foot, arm: Bando 2001 "
        "figs. 6.1-6.3; face, makeup: Huang et al. 2013; see jaxskin list) or a TOML scene "
        "file (format: docs/reference/scene.md on the documentation site; every key with its "
        "default and range: python -m pydoc jaxskin.scene). Writes "
        "DIR/<scene>.png "
        "(or .exr, --format); "
        "with --maps also DIR/<scene>_height.png (16-bit grey), DIR/<scene>_normal.png (the "
        "bump-mapped normal map) and DIR/<scene>_field.png (the mesh with d1 in red and d2 in "
        "green, as in the paper's fig. 3.4). With -D overrides the name gets "
        "_<key>-<value> for each (DIR/hand_material.melanin-0.5.png; past 120 characters "
        "_D-<12 hex digits>, a digest of the overrides; -D name=NAME gives NAME alone), a "
        "sweep "
        "_sweep-<index>_<key>-<value> with a zero-padded index (DIR/hand_sweep-02_"
        "material.melanin-0.25.png; --maps and --glb are written once, for the scene's own "
        "value of the swept key). A file of the same name in DIR is replaced (an input of the "
        "run never is). A scene name must be a plain file name (no '/' or '\\', leading dot "
        "or control character) or it is refused. Everything is checked before "
        "anything is written: every scene, override, sweep, mesh, material, BRDF file, layer "
        "image and polygon, the output folder, that no output is an input, and that the "
        "render fits in memory. All scenes render in one process (or on a Dask cluster, "
        "--cluster); each static configuration compiles once (per worker).",
    )
    r.add_argument("scenes", nargs="+", metavar="SCENE", help="built-in name or TOML file")
    r.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder")
    r.add_argument("--maps", action="store_true",
                   help="also write the texture-space maps (height, normals, fields)")
    r.add_argument("--format", choices=("png", "png16", "exr"), default="png",
                   help="image format: png (8-bit, default), png16 (16-bit PNG), exr (linear "
                   "OpenEXR, float32 RGBA with premultiplied alpha; needs pip install "
                   "'jaxskin[exr]')")
    r.add_argument("--alpha", action="store_true",
                   help="PNG with an alpha channel: alpha = the mesh's coverage of each pixel "
                   "(antialiased with camera.supersample), the colour straight (not "
                   "premultiplied); EXR always has alpha")
    r.add_argument("--glb", action="store_true",
                   help="also write DIR/<scene>.glb: the mesh with its skin colour and the "
                   "wrinkle normal map as textures (opens in Blender or any glTF viewer)")
    r.add_argument("--sweep", action="append", default=[], metavar="KEY=START:STOP:COUNT",
                   help="render COUNT images with a parameter from START to STOP, vmapped in "
                   "batches of 8 values by one compiled program (fewer are padded to 8: a "
                   "value's image has the same bytes in any sweep), e.g. --sweep "
                   "material.melanin=0:1:5; writes "
                   "DIR/<scene>_sweep-<i>_<key>-<value>.png. One --sweep a command (a grid "
                   "of two keys: one command per value of the second, with -D); of several "
                   "scenes, one without the key is rendered once, with a warning")
    overrides(r, "override a scene value, e.g. -D wrinkles.k_scale=1.3, -D "
              "camera.rotate=0,60,0 (a list: numbers with commas, or TOML's [0, 60, 0]) "
              "or -D layer.blush.material=foundation_dark (a shipped material or a "
              "calibrate JSON; paths from the working directory); repeatable; applies to "
              "every scene")
    cluster.add_option(r, f"batch of {batch.SWEEP_BATCH} sweep values, or scene")


def run(args, record: Run) -> int:
    """Check every scene, override, sweep and output name; then render, here or on the
    cluster, and write each unit's files as its result comes back."""
    from .. import maps

    if args.format == "exr" and not maps.exr_available():
        raise InputError("--format exr needs the OpenEXR bindings: pip install 'jaxskin[exr]'")
    if len(args.sweep) > 1:
        raise InputError(f"one --sweep at a time for now (got {len(args.sweep)})")
    outputs = Outputs(args.output)
    # Everything checked before any output: every scene, its inputs, the sweep, memory,
    # the output names (distinct, safe, not an input); then the warnings.
    scenes = _load_scenes(args)
    # A sweep over a parameter some of the scenes have: the others are rendered once, with
    # a warning, as -D does, rather than stopping the batch. None has it: the error.
    swept = [bool(args.sweep) and sweeps(sc, args.sweep[0]) for sc in scenes]
    unswept = [bool(args.sweep) and not here and any(swept) for here in swept]
    plans = _plan(args, scenes, unswept, outputs)
    _warn_unused(args, scenes, unswept)
    record.outputs.append(outputs)
    from ..skin_texture import cache_beside

    with cache_beside(outputs.folder):  # skin.texture's inversion, kept beside the output
        rows = _render_and_write(args, record, outputs, plans)
    print(f"{'scene':<16} {'image':>9} {'files':>6} {'time s':>7}")
    for name, size, n, dt in rows:
        print(f"{name:<16} {size:>9} {n:>6} {dt:>7.2f}")
    print_written(outputs)
    return 0


def _ext(args) -> str:
    return "exr" if args.format == "exr" else "png"


def _load_scenes(args) -> list:
    """Every scene of the command with the `-D` values (one `-D name` for one scene only)."""
    from ..scene import BUILTIN_SCENES, load_scene

    named = [item for item in args.overrides if item.partition("=")[0].strip() == "name"]
    if named and len(args.scenes) > 1:  # every scene's outputs would take the one name
        raise InputError(f"gives all {len(args.scenes)} scenes of the command one name: render "
                         "one scene per command with -D name, or set name in each scene file",
                         f"-D {named[-1]}")
    scenes = []
    for name in args.scenes:
        with reading(name):
            scenes.append(load_scene(name, args.overrides, flag="-D"))
        if name in BUILTIN_SCENES and Path(name).is_file():  # the built-in one wins
            warn(f"'{name}' is the built-in scene; the file {name} here is "
                 f"not read (give ./{name} for it)")
    warn_repeated(args.overrides)
    return scenes


def _plan(args, scenes, unswept, outputs: Outputs) -> list[tuple]:
    """Each scene's sweep checked, its inputs checked (memory included) and recorded, its
    base name made, then every output path planned: `(scene, sweep, {kind: path(s)})`."""
    from ..scene import parse_override

    ext = _ext(args)
    named = []
    for sc, skip in zip(scenes, unswept, strict=True):
        sweep = [] if skip else [parse_sweep(text, sc) for text in args.sweep]
        for (key, _), text in zip(sweep, args.sweep[:len(sweep)], strict=True):
            for item in args.overrides:
                if parse_override(item)[0] == key:
                    raise InputError(f"--sweep {text} sets {key}, so -D {item} would be "
                                     "ignored (and named in every file); give one of them",
                                     key=key)
        count = batch.SWEEP_BATCH if sweep else 1  # per batch: every batch is padded
        outputs.inputs += [Path(p) for p in check_scene(sc, count, args.overrides)]
        adds = [f".{ext}", ".glb" if args.glb else "", "_normal.png" if args.maps else "",
                *sweep_suffixes(sweep, ext)]
        room = max(len(a.encode("utf-8")) for a in adds)  # the longest the outputs add
        named.append((sc, sweep, base_name(sc, args.overrides, room)))
    plans = []
    for sc, sweep, base in named:
        planned = {}
        if sweep:
            planned["sweep"] = [outputs.plan(base + suffix, sc.source)
                                for suffix in sweep_suffixes(sweep, ext)]
        else:
            planned["image"] = outputs.plan(f"{base}.{ext}", sc.source)
        if args.glb:
            planned["glb"] = outputs.plan(f"{base}.glb", sc.source)
        if args.maps:
            for kind in ("height", "normal", "field"):
                planned[kind] = outputs.plan(f"{base}_{kind}.png", sc.source)
        plans.append((sc, sweep, planned))
    return plans


def _warn_unused(args, scenes, unswept) -> None:
    """After every check, warnings rather than errors (`-D` serves every scene): a `-D` or
    `--sweep` a scene does not use, and what its picture will not show."""
    from ..scene import parse_override

    for sc, skip in zip(scenes, unswept, strict=True):
        idle = idle_map_keys(sc)
        for item in unused_overrides(sc, args.overrides):
            if parse_override(item)[0] not in idle:  # an idle map's own line says more
                warn(f"-D {item} changes nothing in scene {sc.name!r} "
                     f"(its material model or settings do not use it"
                     f"{reads_instead(sc, item, args.overrides)})")
        if skip:
            key, _, spec = args.sweep[0].partition("=")
            hint = reads_instead(sc, f"{key.strip()}={spec.split(':')[0]}", args.overrides)
            warn(f"--sweep {args.sweep[0]} changes nothing in scene "
                 f"{sc.name!r} (not one of its parameters{hint}): it is rendered once, "
                 "unswept")
        for line in picture_warnings(sc):
            warn(line)


def _units(args, plans) -> tuple[list, list]:
    """The units of work: a scene's sweep in batches of `batch.SWEEP_BATCH` values (one
    compiled program per configuration), or the scene's one image, and its maps; with
    `(scene index, the unit's output paths or None for maps)` for each."""
    import jax
    import numpy as np

    output = "linear_rgba" if args.format == "exr" else "rgba" if args.alpha else "display"
    units, targets = [], []
    for i, (sc, sweep, planned) in enumerate(plans):
        params = jax.tree.map(np.asarray, sc.params)
        if sweep:
            (key, values), = sweep
            for k, chunk in enumerate(batch.sweep_batches(values)):
                units.append(("images", sc.config, params, key, chunk, output))
                targets.append((i, planned["sweep"][k * len(chunk):(k + 1) * len(chunk)]))
        else:
            units.append(("images", sc.config, params, None, None, output))
            targets.append((i, [planned["image"]]))
        if args.maps or args.glb:
            units.append(("maps", sc.config, params, args.glb))
            targets.append((i, None))
    return units, targets


def _render_and_write(args, record: Run, outputs: Outputs, plans) -> list[tuple]:
    """Run the units here or on the `--cluster`; their results come back in order and are
    written here. Returns a row per scene: `(name, size, files written, seconds)`."""

    units, targets = _units(args, plans)
    seconds, n0 = [0.0] * len(plans), [0] * len(plans)
    rows, empty = [], set()
    with cluster.pool(args.cluster) as pool:
        record.stage = f"rendering {plans[0][0].name}"
        results = pool.map(batch.render_unit, units, desc="render", unit="task")
        for k, ((i, paths), (result, dt)) in enumerate(zip(targets, results, strict=True)):
            sc, sweep, planned = plans[i]
            t0 = time.perf_counter()
            if k == 0 or targets[k - 1][0] != i:
                n0[i] = len(outputs.written)
            if paths is None:
                _write_maps(sc, planned, outputs, result)
            else:
                for path in _write_images(args, sc, result if sweep else [result], paths,
                                          outputs):
                    if i not in empty:  # a black picture, said once per scene
                        empty.add(i)
                        warn(f"{path.name}: {empty_picture(sc)}")
            seconds[i] += dt + time.perf_counter() - t0
            if k + 1 == len(targets) or targets[k + 1][0] != i:  # the scene's last unit
                config = sc.config
                size = f"{config.image}x{config.image_height or config.image}"
                rows.append((sc.name, size, len(outputs.written) - n0[i], seconds[i]))
            if k + 1 < len(targets):
                following = plans[targets[k + 1][0]][0].name
                record.stage = (f"making the maps of {following}"
                                if targets[k + 1][1] is None else f"rendering {following}")
    return rows


def _write_images(args, sc, images, paths, outputs: Outputs):
    """Write each image to its path, one after the other, yielding the path of each
    all-black one as soon as it is written. A non-finite value is an error (`FitError`),
    its file not written: a NaN is a black pixel in a PNG, never written as a picture."""
    import numpy as np

    from .. import maps

    for image, path in zip(images, paths, strict=False):
        bad = int(np.size(image) - np.count_nonzero(np.isfinite(image)))
        if bad:
            raise FitError(f"the render has {bad} non-finite values (NaN or infinity: a value "
                           f"outside what float32 holds?); {path.name} not written", sc.source)
        maps.write_render(image, path, args.format)
        outputs.done(path)
        if not np.any(image):
            yield path


def _write_maps(sc, planned: dict, outputs: Outputs, result: dict) -> None:
    """Write a scene's texture-space maps (--maps) and GLB (--glb) from `result`
    (`batch.scene_maps`: height, normals and the GLB's albedo, made here or on a worker)."""
    from .. import maps, texture

    s = texture.setup(sc.config.texture)  # the mesh and texture space, for the mask and GLB
    if "glb" in planned:
        from ..export import write_glb

        write_glb(s, result["albedo"], result["normals"], planned["glb"])
        outputs.done(planned["glb"])
    if "height" in planned:
        maps.write_height(result["height"], planned["height"])
        outputs.done(planned["height"])
        maps.write_normals(result["normals"], s.mask, planned["normal"])
        outputs.done(planned["normal"])
        maps.write_field_plot(s, planned["field"], f"{sc.name} ({s.mesh.name}): d1 (red), "
                              "d2 (green)", sc.config.rotate)
        outputs.done(planned["field"])
