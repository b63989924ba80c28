"""The gallery: every built-in scene, a melanin × blood grid of the hand, and a scan under
makeup, on one sheet.

    .venv/bin/python benchmarks/gallery.py [--size 320] [--out benchmarks/gallery.png]

Renders each built-in scene at its own settings (only the image size changed) and the Blinn
hand over melanin × blood in 0–1 (one vmapped program per blood value), and the shipped
stand-in scan (`data/meshes/astronaut_face.*`, its texture as the skin through
`skin.texture`) bare, under a sheer foundation, and under the `makeup` scene's full look;
and writes one contact-sheet PNG, linked from the README. Look at it after any change to
what users see; tests/test_golden.py holds the small references that fail when it changes.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
GRID = np.linspace(0.0, 1.0, 5)  # melanin (columns) and blood (rows)


def scene_image(name: str, size: int) -> np.ndarray:
    from jaxskin import render
    from jaxskin.scene import scene_at_width

    scene = scene_at_width(name, size)
    return np.clip(np.asarray(render.render(scene.config, scene.params)), 0.0, 1.0)


def skin_grid(size: int) -> np.ndarray:
    """(blood, melanin, size, size, 3): the Blinn hand over the GRID values of both
    (`jaxskin.skin_grid`, the README's grid, here with the wrinkles)."""
    from jaxskin.skin_grid import skin_grid as grid

    return np.clip(grid(GRID, GRID, size=size, overrides=["view.mode=wrinkles"]), 0.0, 1.0)


SCAN_LOOKS = {  # the makeup scene's layers over the scan: -D overrides per panel
    "scan: bare": [f"layer.{n}.thickness_mm=0"
                   for n in ("foundation", "eyeshadow", "blush", "lipstick")],
    "scan: foundation": ["layer.foundation.thickness_mm=0.001",
                         *(f"layer.{n}.thickness_mm=0" for n in ("eyeshadow", "blush",
                                                                  "lipstick"))],
    "scan: full look": ["layer.foundation.thickness_mm=0.001"],
}


def scan_images(size: int) -> dict[str, np.ndarray]:
    """The stand-in scan in the `makeup` scene (`SCAN_LOOKS`), biophysical skin from its
    texture (inverted once, then kept in memory)."""
    from jaxskin import render
    from jaxskin.io import data_dir
    from jaxskin.scene import scene_at_width

    mesh = data_dir() / "meshes" / "astronaut_face"
    scan = [f"mesh.file={mesh}.obj", "material.model=biophysical",
            f"skin.texture={mesh}.png"]
    out = {}
    for name, extra in SCAN_LOOKS.items():
        scene = scene_at_width("makeup", size, [*scan, *extra])
        out[name] = np.clip(np.asarray(render.render(scene.config, scene.params)), 0.0, 1.0)
    return out


def contact_sheet(scenes: dict[str, np.ndarray], grid: np.ndarray, path: Path,
                  scans: dict[str, np.ndarray] | None = None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jaxskin.io import atomic_write

    names = list(scenes)
    scans = scans or {}
    mosaic = [names, [".", *["grid"] * (len(names) - 2), "."]]
    if scans:
        side = (len(names) - len(scans)) // 2
        mosaic.append(["."] * side + list(scans) + ["."] * (len(names) - len(scans) - side))
    fig, axes = plt.subplot_mosaic(mosaic, figsize=(3.0 * len(names), 9.5 + 3.2 * bool(scans)),
                                   dpi=110, height_ratios=[1.0, 1.6, 1.0][:len(mosaic)],
                                   layout="constrained", facecolor="black")
    for name, image in {**scenes, **scans}.items():
        axes[name].imshow(image)
        axes[name].set_title(name, color="white", fontsize=12)
        axes[name].axis("off")
    b = grid.shape[0]
    tiles = np.concatenate([np.concatenate(list(grid[i]), axis=1) for i in range(b)], axis=0)
    ax = axes["grid"]
    ax.imshow(tiles[::-1], extent=(-0.125, 1.125, -0.125, 1.125))  # blood up, melanin right
    ax.set_xticks(GRID)
    ax.set_yticks(GRID)
    ax.tick_params(colors="white")
    ax.set_xlabel("material.melanin", color="white")
    ax.set_ylabel("material.blood", color="white")
    ax.set_title("Blinn skin colour over melanin × blood", color="white", fontsize=11)
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format="png", facecolor="black")
    plt.close(fig)


def main(argv=None) -> int:
    from jaxskin.scene import BUILTIN_SCENES

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=320, help="image pixels across per scene")
    p.add_argument("--grid-size", type=int, default=96, help="pixels across per grid tile")
    p.add_argument("--out", type=Path, default=HERE / "gallery.png", help="the PNG to write")
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    scenes = {name: scene_image(name, args.size) for name in BUILTIN_SCENES}
    grid = skin_grid(args.grid_size)
    contact_sheet(scenes, grid, args.out, scan_images(args.size))
    print(f"wrote {args.out} ({time.perf_counter() - t0:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
