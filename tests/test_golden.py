"""Golden images: every built-in scene, rendered small, against committed references.

A change in what users see fails here until the references are updated on purpose:

    JAXSKIN_UPDATE_GOLDEN=1 .venv/bin/python -m pytest tests/test_golden.py

(then look at the new tests/golden/*.png before committing them). The comparison is CIEDE2000
between the rendered and the reference sRGB images; on failure a side-by-side picture
(reference | render | ΔE×10) is written next to pytest's temporary files and named in the message.
"""

from __future__ import annotations

import os
from pathlib import Path

import colour
import imageio.v3 as iio
import numpy as np
import pytest

from jaxskin import render
from jaxskin.maps import write_image
from jaxskin.scene import BUILTIN_SCENES, scene_at_width

GOLDEN = Path(__file__).resolve().parent / "golden"
SIZE = 128  # image pixels across; the scenes' own textures, fields and materials are kept
UPDATE = os.environ.get("JAXSKIN_UPDATE_GOLDEN", "") not in ("", "0")

# Re-rendering on this machine reproduces the references exactly (ΔE2000 0.0). The tolerance
# leaves room for another CPU or XLA version (rounding that moves a pixel by one 8-bit level
# gives ΔE2000 up to ~0.5) while a visible change of colour or light fails: a mean shift of 0.3
# over the image or one percent of pixels off by more than 2 (a furrow moved, an edge shifted).
MEAN_DE, P99_DE = 0.3, 2.0


def _to_lab(rgb8: np.ndarray) -> np.ndarray:
    rgb = rgb8[..., :3].astype(np.float64) / 255.0
    xyz = colour.sRGB_to_XYZ(rgb)
    return colour.XYZ_to_Lab(xyz)


def _render(name: str) -> np.ndarray:
    # The references pin the sequential furrow program, which `wrinkles.method = "auto"`
    # picks for these 512² textures on a CPU; on a GPU `auto` picks the parallel one (other
    # furrows of the same character), so the method is named to compare like with like.
    scene = scene_at_width(name, SIZE, ["wrinkles.method=sequential"])
    image = np.asarray(render.render(scene.config, scene.params))
    return np.round(np.clip(image, 0.0, 1.0) * 255).astype(np.uint8)


@pytest.mark.parametrize("name", BUILTIN_SCENES)
def test_builtin_scene_matches_its_golden_image(name, tmp_path):
    image = _render(name)
    ref_path = GOLDEN / f"{name}.png"
    if UPDATE:
        write_image(image / 255.0, ref_path)
        pytest.skip(f"reference written: {ref_path}")
    assert ref_path.is_file(), f"no reference {ref_path}; run with JAXSKIN_UPDATE_GOLDEN=1"
    ref = iio.imread(ref_path)
    assert ref.shape[:2] == image.shape[:2], f"size {image.shape} != reference {ref.shape}"
    de = colour.delta_E(_to_lab(ref), _to_lab(image), method="CIE 2000")
    mean, p99 = float(de.mean()), float(np.percentile(de, 99))
    if mean > MEAN_DE or p99 > P99_DE:
        heat = np.clip(de * 10.0, 0, 255).astype(np.uint8)
        sheet = np.concatenate([ref[..., :3], image[..., :3],
                                np.stack([heat] * 3, axis=-1)], axis=1)
        iio.imwrite(tmp_path / f"{name}_golden_diff.png", sheet)
        pytest.fail(f"{name}: ΔE2000 mean {mean:.3f} (limit {MEAN_DE}), p99 {p99:.3f} "
                    f"(limit {P99_DE}); reference | render | ΔE×10 in "
                    f"{tmp_path / f'{name}_golden_diff.png'}")


def test_golden_comparison_catches_a_visible_change():
    """The tolerance is not so loose that a 3 % exposure change or a shifted edge passes."""
    name = "hand"
    ref = iio.imread(GOLDEN / f"{name}.png") if not UPDATE else _render(name)
    brighter = np.clip(np.round(ref.astype(np.float64) * 1.03), 0, 255).astype(np.uint8)
    de = colour.delta_E(_to_lab(ref), _to_lab(brighter), method="CIE 2000")
    assert de.mean() > MEAN_DE or np.percentile(de, 99) > P99_DE
    shifted = np.roll(ref, 2, axis=1)
    de = colour.delta_E(_to_lab(ref), _to_lab(shifted), method="CIE 2000")
    assert de.mean() > MEAN_DE or np.percentile(de, 99) > P99_DE
