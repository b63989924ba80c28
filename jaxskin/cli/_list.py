"""`jaxskin list`: one line for each built-in thing a scene can name."""

from __future__ import annotations

import re
from pathlib import Path

from ._process import Run, raise_pending

__all__ = ["add_parser", "run"]


def add_parser(sub) -> None:
    """The `jaxskin list` subcommand and its options."""
    sub.add_parser("list", help="list the built-in scenes, meshes, materials, BRDF presets, "
                   "illuminants and spectral steps",
                   description="One line for each built-in thing a scene can name.")


def run(args, record: Run) -> int:
    """One line per built-in scene, mesh, material, BRDF preset, illuminant, spectral step."""
    from .. import cosmetics, scene, spectral
    from ..mesh import BUILTIN as MESHES

    raise_pending()  # after the imports: a signal held inside one is raised here, before
    # any line is printed

    def first_comment(path: Path, width: int = 100) -> str:
        """The first sentence of the scene file's opening comment (at most `width` long)."""
        lines = path.read_text(encoding="utf-8").splitlines()
        text = " ".join(line.lstrip("# ").strip() for line in
                        lines[:next((i for i, t in enumerate(lines) if not t.startswith("#")),
                                    len(lines))])
        text = re.split(r"(?<=\.) (?=[A-Z])", text)[0]
        return text if len(text) <= width else text[:width].rsplit(" ", 1)[0] + " …"

    rows = [("scene", name, first_comment(path)) for name, path in scene.builtin_scenes().items()]
    rows += [("mesh", name, f"data/meshes/{file}") for name, file in MESHES.items()]
    for name in cosmetics.shipped_materials():
        rows.append(("material", name, "a calibrated cosmetic (S, K per mm; data/materials)"))
    rows.append(("brdf", "skin", "Lafortune preset: pbrt-v1's 3-lobe fit to measured skin "
                 "(material.brdf; or a JSON from jaxskin fit-brdf)"))
    for name in spectral.ILLUMINANTS:
        rows.append(("illuminant", name, f"CIE illuminant {name} (spectral.illuminant)"))
    for step in spectral.STEPS:
        n = len(spectral.Grid(step).wavelengths)
        rows.append(("step", f"{step}", f"{step} nm: {n} bands, 380-780 nm "
                     f"(spectral.step = {step})"))
    for kind, name, text in rows:
        print(f"{kind:<10} {name:<20} {text}")
    return 0
