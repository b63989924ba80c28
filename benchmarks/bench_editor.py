"""The editor's latencies (issues 15 and 38), warm, as the server spends them per request:
apply the change (`Session.set` / `Session.paint_stroke`), render, encode the PNG. HTTP adds
about a millisecond on 127.0.0.1 and is left out.

- a parameter change: `material.melanin` on the hand at 512² (aim: 50 ms while dragging);
- a field edit: one edit's d1 changed, new furrows (aim: 0.5 s);
- a brush stroke: a 60-pixel segment of paint on the makeup face at 512² (aim: 100 ms
  while dragging).

On release (final) the aim is 250 ms for either (issue 38).

Each as the page asks for it while dragging (`preview`: one sample per pixel) and when the
drag ends (`final`: the scene's own supersampling, the image Save reproduces). Median of 5
after a warm-up; the first call of each kind (compiles) is printed apart.

    .venv/bin/python benchmarks/bench_editor.py [--write]
"""

from __future__ import annotations

import os
import statistics
import sys
import tempfile
import time

from common import machine, table, write_section

from jaxskin import compile_cache
from jaxskin.editor import Session

REPEAT = 5
NOTE = """\
Server time per request: the change applied, the view rendered, the image encoded (PNG for
a final render, the same samples as BMP for a preview). "First call" includes compiling
(a field edit's first furrow program, the makeup's first preview); after it no parameter
change, field edit or stroke compiles again (`tests/test_editor.py` counts the compiled
programs). The machine is shared with other work (the load average above): the wall times
then grow with the load, and the CPU time (both cores together) says roughly what an idle
2-core machine needs: between CPU/2 and CPU. A preview of the makeup face renders one sample
per pixel and its spectra at 20 nm (`editor._render.PREVIEW_STEP`; the scene's 10 nm on
release); the cosmetics render's spectral work skips the layers a chunk of texels lacks
(`shading.layered._forward_chunked`), and a stroke repaints the texel rows it reaches
(2-3 ms with the new coverage row)."""


def timed(step, repeat=REPEAT):
    """(first call, median of `repeat` more, median CPU time of those) seconds of
    `step(i)`. The CPU time is the process's, over all its threads: on a machine shared
    with other work the wall time grows with the load, the CPU time much less."""
    t0 = time.perf_counter()
    step(0)
    first = time.perf_counter() - t0
    times, cpu = [], []
    for i in range(1, repeat + 1):
        t0, c0 = time.perf_counter(), time.process_time()
        step(i)
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return first, statistics.median(times), statistics.median(cpu)


def measure() -> list[tuple]:
    rows = []
    out = tempfile.mkdtemp(prefix="bench_editor_")
    hand = Session("hand", out)
    for preview in (True, False):
        hand.image_file(preview)

        def param(i, preview=preview):
            hand.set({"material.melanin": 0.1 + 0.05 * i})
            hand.image_file(preview)
        rows.append(("parameter change (material.melanin)", "hand 512²", preview,
                     *timed(param), 0.05 if preview else 0.25))
    edits = [{"vertex": e.vertex, "at": e.at and list(e.at), "d1": list(e.d1), "d2": list(e.d2),
              "weight": e.weight} for e in hand.scene.edits]
    for e in edits:
        e.pop("at" if e["vertex"] is not None else "vertex")
    for preview in (True, False):
        def edit(i, preview=preview):
            changed = [dict(e) for e in edits]
            changed[0]["d1"] = [0.5 + 0.01 * i + (0.2 if preview else 0), 0.9, 0.0]
            hand.set({"fields.edit": changed})
            hand.image_file(preview)
        rows.append(("field edit (new furrows)", "hand 512²", preview, *timed(edit), 0.5))
    face = Session("makeup", out)
    for preview in (True, False):
        face.image_file(preview)

        def stroke(i, preview=preview):
            y = 200 + 8 * i
            face.paint_stroke(f"s{preview}", "blush", [[200, y], [260, y]], 12, 0.5)
            face.image_file(preview)
        rows.append(("brush stroke (60 px segment)", "makeup 512²", preview,
                     *timed(stroke), 0.1 if preview else 0.25))
    return rows


def main(argv=()) -> int:
    compile_cache.enable()
    rows = measure()
    body = table(["request", "scene", "render", "first call", "warm (median)",
                  "CPU time (median)", "aim"],
                 [(what, scene, "preview" if p else "final", f"{first * 1e3:.0f} ms",
                   f"{warm * 1e3:.0f} ms", f"{cpu * 1e3:.0f} ms", f"{aim * 1e3:.0f} ms")
                  for what, scene, p, first, warm, cpu, aim in rows])
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    body += f"\n\nLoad average at the end: {load:.1f} (on {os.cpu_count()} cores)."
    print(body)
    if "--write" in argv:
        write_section("editor", "## The editor's latencies (issue 15)\n\n"
                      f"Command: `.venv/bin/python benchmarks/bench_editor.py --write`. "
                      f"Machine: {machine()}.\n\n" + body + "\n\n" + NOTE)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
