"""A 64-image sweep: wall time here against two Dask workers on this machine (issue 17).

    .venv/bin/python benchmarks/bench_cluster.py [--size 128] [--count 64]

Runs `jaxskin render hand --sweep material.melanin=0:1:COUNT` (texture and image SIZE)
four times, each a fresh `jaxskin` process timed end to end (imports, compile or the
compilation cache, render, PNG writes): here, twice (the second finds the first's compiled
programs in the persistent cache); on a `LocalCluster` of two worker processes (one thread
each) started beforehand, whose workers have not rendered yet (they import JAX and load or
compile on their first task); on the same cluster again (workers warm). Checks that the
four folders hold the same bytes and prints one Markdown table.
"""

from __future__ import annotations

import argparse
import hashlib
import logging
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _run(argv, out: Path) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "jaxskin", *argv, "-o", str(out)], check=True,
                   capture_output=True)
    return time.perf_counter() - t0


def _digest(folder: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(folder.iterdir()):
        h.update(p.name.encode() + p.read_bytes())
    return h.hexdigest()


def main(argv=None) -> int:
    from distributed import LocalCluster

    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--count", type=int, default=64)
    a = ap.parse_args(argv)
    render = ["render", "hand", "-D", f"texture.size={a.size}", "-D", f"camera.size={a.size}",
              "--sweep", f"material.melanin=0:1:{a.count}"]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        rows.append(("here (one process)", _run(render, tmp / "here")))
        rows.append(("here, again (compilation cache warm)", _run(render, tmp / "here2")))
        with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                          dashboard_address=None, silence_logs=logging.ERROR) as lc:
            cl = ["--cluster", lc.scheduler_address]
            rows.append(("2 workers, first run", _run(render + cl, tmp / "cold")))
            rows.append(("2 workers, again", _run(render + cl, tmp / "warm")))
        same = len({_digest(tmp / d) for d in ("here", "here2", "cold", "warm")}) == 1
    print(f"{a.count} images, hand, texture and image {a.size}²; the same bytes: {same}\n")
    print("| run | wall s | × here |\n|---|---|---|")
    for name, t in rows:
        print(f"| {name} | {t:.1f} | {t / rows[0][1]:.2f} |")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
