"""`jaxskin fit-brdf`: Lafortune lobes fitted to BRDF samples (`jaxskin.fitting.brdf`)."""

from __future__ import annotations

import time
from pathlib import Path

from .. import cluster
from ..io import InputError
from ..outputs import Outputs
from ._options import no_report, number, seed
from ._process import Run
from ._terminal import note, warn

__all__ = ["add_parser", "run"]


def add_parser(sub) -> None:
    """The `jaxskin fit-brdf` subcommand and its options."""
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
    b.add_argument("--lobes", type=number(int, 1, 16), default=3, metavar="N",
                   help="lobes per channel, 1-16 (3)")
    b.add_argument("--starts", type=number(int, 1, 1024), default=8, metavar="S",
                   help="starts per channel, 1-1024, half from typical lobe shapes, half "
                   "random (8); the best finite fit wins")
    seed(b)
    no_report(b, "JSON")
    cluster.add_option(b, "RGB channel")


def run(args, record: Run) -> int:
    """Read and check the samples, fit the lobes (per channel, here or on the cluster),
    write the material JSON and the report."""
    from jaxskin import formats
    from jaxskin.fitting import brdf

    out = Path(args.output)
    if out.is_dir():
        raise InputError("-o: expected the file to write (OUT.json), but this is a folder",
                         out)
    if out.suffix.lower() != ".json":
        raise InputError(f"-o: expected a .json file name (the fitted lobes; the report is "
                         f"written beside it as .png), got {out.name!r}", out)
    outputs = Outputs(out.parent, [args.file], named_files=False)  # -o OUT.json: named
    out = outputs.plan(out.name, "the fit")
    report = None if args.no_report else outputs.plan(out.with_suffix(".png").name,
                                                      "the report")
    samples = brdf.read_samples(args.file)
    brdf.check_samples(samples, args.lobes)
    for line in samples.notes:
        note(line)
    from .. import resources

    resources.check_memory(resources.fit_brdf_bytes(len(samples.f), args.lobes, args.starts),
                           f"fitting {args.lobes} lobes x {args.starts} starts to "
                           f"{len(samples.f)} samples", args.file,
                           hint="use fewer --starts or --lobes")
    record.outputs.append(outputs)
    record.stage = "fitting"
    print(f"fitting {args.lobes} lobes x {args.starts} starts x 3 channels to "
          f"{len(samples.f)} samples ...", flush=True)
    t0 = time.perf_counter()
    with cluster.pool(args.cluster) as pool:
        result = brdf.fit(samples, lobes=args.lobes, starts=args.starts, seed=args.seed,
                          map_units=pool.mapper(desc="fit-brdf", unit="channel"))
    seconds = time.perf_counter() - t0
    stats = result.stats()
    formats.write_lafortune(result.params, out, fit={"source": Path(args.file).name, **stats})
    outputs.done(out)
    if report is not None:
        brdf.write_report(samples, result, report)
        outputs.done(report)
    print(f"{'channel':<8} {'rel. RMS error':>14} {'failed starts':>13} {'steps':>6}")
    for k, name in enumerate("RGB"):
        done = bool(result.converged[k, result.best[k]])  # the best start's own solver flag
        print(f"{name:<8} {result.rel_rms[k]:>14.2%} {stats['failed_starts'][k]:>13} "
              f"{stats['steps_of_best'][k]:>6}" + ("" if done else " (not converged: the "
                                                   "solver stopped at its step limit)"))
    print(f"wrote {out}" + ("" if report is None else f" and {report}") + f" ({seconds:.1f} s)")
    for line in brdf.fit_warnings(result):
        warn(line)
    return 0

