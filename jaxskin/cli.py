"""The `jaxskin` command line.

    jaxskin --version
    jaxskin calibrate FILE.csv [FILE.csv ...] -o OUTDIR   # S(λ), K(λ) of cosmetics
    jaxskin fit-brdf FILE.csv -o OUT.json [--lobes N]     # Lafortune lobes
    jaxskin render SCENE [SCENE ...] -o DIR --maps        # wrinkle height and normal maps

Bad input (a file, a column, a value) is reported as one line `jaxskin: error: …` with exit
code 2 and no traceback. Output files are written under temporary names and renamed.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from . import __version__
from .io import FitError, InputError

EXIT_INPUT = 2
EXIT_FAILED = 1


def _enable_compilation_cache() -> None:
    """Persist compiled programs across runs (JAXSKIN_NO_COMPILE_CACHE=1 switches it off)."""
    if os.environ.get("JAXSKIN_NO_COMPILE_CACHE", "") not in ("", "0"):
        return
    import jax

    root = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    path = os.environ.get("JAXSKIN_CACHE_DIR") or os.path.join(root, "jaxskin", "jax")
    try:
        os.makedirs(path, exist_ok=True)
    except OSError:
        return  # an unwritable home is no reason to fail; we just compile again
    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="jaxskin",
        description="Differentiable rendering of human skin and cosmetics in JAX, with fitting.",
        epilog="Environment: JAXSKIN_NO_COMPILE_CACHE=1 turns off the compilation cache kept in "
        "$XDG_CACHE_HOME/jaxskin (or JAXSKIN_CACHE_DIR). Bad input exits with code 2.",
    )
    p.add_argument("--version", action="version", version=f"jaxskin {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    c = sub.add_parser(
        "calibrate",
        help="fit Kubelka–Munk S(λ), K(λ) of cosmetics to spectroradiometer CSVs",
        description="Fit scattering S(λ) and absorption K(λ) (per mm) of each cosmetic from a "
        "CSV of thin-layer (R_<X>mm), opaque (R_inf) and background (R_g) reflectances, or raw "
        "radiances (E_… and E_white). Writes OUTDIR/<name>.json (the material file the "
        "renderer reads) and OUTDIR/<name>.png (a report). Every file is checked before any "
        "fit runs: one bad file writes nothing. The CSV format is in the README.",
    )
    c.add_argument("files", nargs="+", metavar="FILE.csv", help="measurement CSVs")
    c.add_argument("-o", "--output", required=True, metavar="OUTDIR",
                   help="folder for <name>.json and <name>.png (created if missing)")
    c.add_argument("--thickness", type=float, metavar="MM",
                   help="thickness in mm of a bare 'R' column (overrides '# thickness_mm:')")
    c.add_argument("--percent", action="store_true",
                   help="reflectance columns are in percent (0–100) instead of 0–1")
    c.add_argument("--smooth", type=float, default=0.0, metavar="W",
                   help="smoothness prior: neighbouring bands' log S and log K differ by about "
                   "1/W (a Gaussian prior weighed against readings of σ = --noise); 0 (default) "
                   "fits each band on its own; 20 allows about 5%% per band")
    c.add_argument("--noise", type=float, default=None, metavar="σ",
                   help="standard deviation of one reflectance reading (default 0.002); a band "
                   "is identifiable when some thin layer and the background each differ from "
                   "R_inf by more than 3σ")
    c.add_argument("--extrapolate", choices=("hold", "linear"), default=None,
                   help="how the renderer may extend S, K beyond the measured wavelengths to "
                   "its 380-780 nm grid: hold the end values, or continue log S, log K "
                   "linearly; without it a material that does not cover the grid is refused "
                   "at render time (calibrate warns)")
    c.add_argument("--no-report", action="store_true", help="write the JSON only, no PNG")

    r = sub.add_parser(
        "render",
        help="render scenes to PNG (and their texture-space maps)",
        description="Render one or more scenes: a built-in name (hand, foot, arm: Bando 2001 "
        "figs. 6.1-6.3) or a TOML scene file (format in the README). Writes DIR/<scene>.png; "
        "with --maps also DIR/<scene>_height.png (16-bit grey), DIR/<scene>_normal.png (the "
        "bump-mapped normal map) and DIR/<scene>_field.png (the mesh with d1 in red and d2 in "
        "green, as in the paper's fig. 3.4). Every scene is checked before anything is "
        "written. All scenes render in one process; each static configuration compiles once.",
    )
    r.add_argument("scenes", nargs="+", metavar="SCENE", help="built-in name or TOML file")
    r.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder")
    r.add_argument("--maps", action="store_true",
                   help="also write the texture-space maps (height, normals, fields)")
    r.add_argument("--glb", action="store_true",
                   help="also write DIR/<scene>.glb: the mesh with its skin colour and the "
                   "wrinkle normal map as textures (opens in Blender or any glTF viewer)")
    r.add_argument("--sweep", action="append", default=[], metavar="KEY=START:STOP:COUNT",
                   help="render COUNT images with a parameter from START to STOP, vmapped in "
                   "one compiled program, e.g. --sweep material.melanin=0:1:5; writes "
                   "DIR/<scene>_<key>=<value>.png")
    r.add_argument("-D", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene value, e.g. -D wrinkles.k_scale=1.3 (repeatable; "
                   "applies to every scene)")

    b = sub.add_parser(
        "fit-brdf",
        help="fit Lafortune lobes to BRDF samples",
        description="Fit the diffuse term ρd and N Lafortune lobes (Cxy, Cz, n) per RGB channel "
        "to BRDF samples: a CSV with theta_in_deg, phi_in_deg, theta_out_deg, phi_out_deg "
        "(or unit vectors wi_x, wi_y, wi_z, wo_x, wo_y, wo_z; local frame, z = normal), R, G, B "
        "in 1/sr, and an optional weight column. Writes OUT.json, the material file the "
        "renderer reads ('diffuse' is ρd; the model divides by π), with the relative RMS error "
        "per channel, and OUT.png, in-plane slices of samples and fit.",
    )
    b.add_argument("file", metavar="FILE.csv", help="BRDF samples")
    b.add_argument("-o", "--output", required=True, metavar="OUT.json",
                   help="the material file to write (the report goes beside it as .png)")
    b.add_argument("--lobes", type=int, default=3, metavar="N", help="lobes per channel (3)")
    b.add_argument("--starts", type=int, default=8, metavar="S",
                   help="starts per channel, half from typical lobe shapes, half random (8); "
                   "the best finite fit wins")
    b.add_argument("--seed", type=int, default=0, help="seed of the random starts (0)")
    b.add_argument("--no-report", action="store_true", help="write the JSON only, no PNG")
    return p


def _calibrate(args) -> int:
    from jaxskin.fitting import km as fit_km
    from jaxskin.fitting.measurements import read_measurement

    noise = fit_km.DEFAULT_NOISE if args.noise is None else args.noise
    if not 0 <= noise <= fit_km.MAX_NOISE:
        raise InputError(f"--noise must be in [0, {fit_km.MAX_NOISE:g}] (a reflectance "
                         f"standard deviation), got {args.noise}")
    if not 0 <= args.smooth <= fit_km.MAX_SMOOTH:
        raise InputError(f"--smooth must be in [0, {fit_km.MAX_SMOOTH:g}], got {args.smooth}")
    out = Path(args.output)
    inputs = {Path(f).resolve() for f in args.files}
    # Check everything first: a bad file anywhere means nothing is written.
    measurements, names = [], {}
    for f in args.files:
        m = read_measurement(f, thickness_mm=args.thickness, percent=args.percent)
        if m.name in names:
            raise InputError(f"name '{m.name}' is also the name of {names[m.name]}; "
                             "give each a distinct '# name:'", f)
        names[m.name] = f
        for ext in (".json", ".png"):
            if (out / (m.name + ext)).resolve() in inputs:
                raise InputError("the output would overwrite this input; choose another -o", f)
        if not fit_km.identifiable(m, noise).any():
            fit_km.fit(m, noise=noise)  # raises the InputError that explains why
        measurements.append(m)

    from tqdm import tqdm

    from jaxskin.fitting.report import write_report
    from jaxskin.formats import write_json
    from jaxskin.spectral import Grid

    grid = Grid().wavelengths
    for m in measurements:
        for note in m.notes:
            print(f"jaxskin: note: {note}", file=sys.stderr)
        wl = m.wavelength_nm
        if args.extrapolate is None and (wl[0] > grid[0] or wl[-1] < grid[-1]):
            print(f"jaxskin: warning: {m.path}: covers {wl[0]:g}-{wl[-1]:g} nm, not the "
                  f"renderer's {grid[0]:g}-{grid[-1]:g} nm: the material will be refused at "
                  "render time; pass --extrapolate hold|linear to allow it", file=sys.stderr)

    rows = []
    for m in tqdm(measurements, desc="calibrate", unit="file", disable=None):
        t0 = time.perf_counter()
        result = fit_km.fit(m, smooth=args.smooth, noise=noise)
        write_json(result.to_json(m, extrapolate=args.extrapolate), out / f"{m.name}.json")
        if not args.no_report:
            write_report(m, result, out / f"{m.name}.png")
        rows.append((m.name, result, time.perf_counter() - t0))
    print(f"{'material':<24} {'bands':>5} {'identifiable':>12} {'rmse':>9} {'steps':>5} "
          f"{'time s':>7}")
    for name, r, dt in rows:
        flag = "" if r.converged else "  (not converged: see report)"
        print(f"{name:<24} {len(r.wavelength_nm):>5} {int(r.identifiable.sum()):>12} "
              f"{r.rmse:>9.2e} {r.steps:>5} {dt:>7.2f}{flag}")
    print(f"wrote {len(rows)} material(s) to {out}/")
    return 0


def _parse_sweep(text: str, params: dict):
    """`key=start:stop:count` over a scalar parameter → (key, values)."""
    import numpy as np

    key, _, spec = text.partition("=")
    parts = spec.split(":")
    try:
        start, stop, count = float(parts[0]), float(parts[1]), int(parts[2])
        ok = len(parts) == 3 and count >= 1
    except (ValueError, IndexError):
        ok = False
    if not ok:
        raise InputError(f"--sweep expects key=start:stop:count, got {text!r}")
    if key not in params or params[key].ndim != 0:
        scalars = ", ".join(k for k, v in params.items() if getattr(v, "ndim", 1) == 0)
        raise InputError(f"--sweep: '{key}' is not a scalar parameter of this scene; "
                         f"parameters: {scalars}")
    return key, np.linspace(start, stop, count)


def _render(args) -> int:
    import jax
    import jax.numpy as jnp
    import numpy as np
    from tqdm import tqdm

    from . import maps, render, texture
    from .scene import load_scene

    scenes = [load_scene(name, args.overrides) for name in args.scenes]
    names = [sc.name for sc in scenes]
    if len(set(names)) != len(names):
        raise InputError(f"two scenes are both named {max(names, key=names.count)!r}; their "
                         "outputs would collide (set 'name' in the scene file)")
    if len(args.sweep) > 1:
        raise InputError(f"one --sweep at a time for now (got {len(args.sweep)})")
    # Everything checked before any output: static setup (mesh, projection, fields), the
    # parameters (a Lafortune file is loaded here) and the sweep's key against them.
    sweeps = []
    for sc in scenes:
        texture.setup(sc.config.texture)
        sweeps.append([_parse_sweep(text, sc.params) for text in args.sweep])
    out = Path(args.output)
    rows = []
    for sc, sweep in tqdm(list(zip(scenes, sweeps, strict=True)), desc="render", unit="scene",
                          disable=None):
        t0 = time.perf_counter()
        config, params = sc.config, sc.params
        if sweep:
            (key, values), = sweep
            batch = jax.jit(jax.vmap(lambda v, a, key=key, params=params, config=config:
                                     render.render_prepared(config, {**params, key: v}, a),
                                     in_axes=(0, None)))
            images = batch(jnp.asarray(values, jnp.float32), render.prepare(config).arrays)
            for v, image in zip(values, np.asarray(images), strict=True):
                maps.write_image(image, out / f"{sc.name}_{key}={v:g}.png")
            written = len(values)
        else:
            maps.write_image(np.asarray(render.render(config, params)), out / f"{sc.name}.png")
            written = 1
        if args.maps or args.glb:
            s = texture.setup(config.texture)
            result = texture.texture_maps(config, params)
        if args.glb:
            from .export import write_glb

            albedo = render.albedo(config, params)
            write_glb(s, np.asarray(albedo), result["normals"], out / f"{sc.name}.glb")
            written += 1
        if args.maps:
            maps.write_height(result["height"], out / f"{sc.name}_height.png")
            maps.write_normals(result["normals"], s.mask, out / f"{sc.name}_normal.png")
            maps.write_field_plot(s, out / f"{sc.name}_field.png")
            written += 3
        size = f"{config.image}x{config.image_height or config.image}"
        rows.append((sc.name, size, written, time.perf_counter() - t0))
    print(f"{'scene':<16} {'image':>9} {'files':>6} {'time s':>7}")
    for name, size, n, dt in rows:
        print(f"{name:<16} {size:>9} {n:>6} {dt:>7.2f}")
    print(f"wrote {sum(r[2] for r in rows)} file(s) to {out}/")
    return 0


def _fit_brdf(args) -> int:
    from jaxskin import formats
    from jaxskin.fitting import brdf

    if args.lobes < 1:
        raise InputError(f"--lobes must be >= 1, got {args.lobes}")
    if args.starts < 1:
        raise InputError(f"--starts must be >= 1, got {args.starts}")
    out = Path(args.output)
    report = out.with_suffix(".png")
    samples = brdf.read_samples(args.file)
    for target in (out, report):
        if target.resolve() == Path(args.file).resolve():
            raise InputError("the output would overwrite the input; choose another -o",
                             args.file)
    print(f"fitting {args.lobes} lobes x {args.starts} starts x 3 channels to "
          f"{len(samples.f)} samples ...", flush=True)
    t0 = time.perf_counter()
    result = brdf.fit(samples, lobes=args.lobes, starts=args.starts, seed=args.seed)
    seconds = time.perf_counter() - t0
    stats = result.stats()
    formats.write_lafortune(result.params, out, fit={"source": Path(args.file).name, **stats})
    if not args.no_report:
        brdf.write_report(samples, result, report)
    print(f"{'channel':<8} {'rel. RMS error':>14} {'failed starts':>13} {'steps':>6}")
    for k, name in enumerate("RGB"):
        print(f"{name:<8} {result.rel_rms[k]:>14.2%} {stats['failed_starts'][k]:>13} "
              f"{stats['steps_of_best'][k]:>6}")
    print(f"wrote {out}" + ("" if args.no_report else f" and {report}") + f" ({seconds:.1f} s)")
    return 0


def main(argv=None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    _enable_compilation_cache()
    try:
        commands = {"calibrate": _calibrate, "fit-brdf": _fit_brdf, "render": _render}
        return commands[args.command](args)
    except InputError as e:
        print(f"jaxskin: error: {e}", file=sys.stderr)
        return EXIT_INPUT
    except FitError as e:
        print(f"jaxskin: error: {e}", file=sys.stderr)
        return EXIT_FAILED


if __name__ == "__main__":
    sys.exit(main())
