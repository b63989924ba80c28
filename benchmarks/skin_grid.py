"""Write benchmarks/skin_grid.png: the hand over melanin 0–1 (columns) and blood 0–1 (rows),
Blinn with `shading.blinn`'s skin colour (the README shows it).

    .venv/bin/python benchmarks/skin_grid.py
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from common import save_figure  # noqa: E402

from jaxskin.skin_grid import skin_grid  # noqa: E402

OUT = Path(__file__).resolve().parent / "skin_grid.png"
MELANIN = np.linspace(0.0, 1.0, 6)
BLOOD = np.linspace(0.0, 1.0, 3)
SIZE = 96


def main() -> None:
    images = np.clip(skin_grid(MELANIN, BLOOD, size=SIZE), 0.0, 1.0)
    rows, cols = images.shape[:2]
    sheet = images.transpose(0, 2, 1, 3, 4).reshape(rows * SIZE, cols * SIZE, 3)
    fig, ax = plt.subplots(figsize=(cols * 1.0 + 0.8, rows * 1.0 + 0.6), dpi=100)
    ax.imshow(sheet, interpolation="nearest")
    ax.set_xticks((np.arange(cols) + 0.5) * SIZE, [f"{v:.1f}" for v in MELANIN])
    ax.set_yticks((np.arange(rows) + 0.5) * SIZE, [f"{v:.1f}" for v in BLOOD])
    ax.set_xlabel("material.melanin")
    ax.set_ylabel("material.blood")
    ax.tick_params(length=0, labelsize=8)
    for side in ax.spines.values():
        side.set_visible(False)
    fig.tight_layout(pad=0.3)
    save_figure(fig, OUT)


if __name__ == "__main__":
    main()
