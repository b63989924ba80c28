"""Sequential against parallel furrows, side by side: `benchmarks/furrows_side_by_side.png`.

    python benchmarks/furrow_pictures.py       # about 3 minutes on 2 cores

Rows: the built-in hand, arm (cylindrical) and face. Columns: the height field (before
noise) of the sequential program and of the parallel one at 512², then the same at 2048²
as a 512² crop at full resolution (the middle of the texture), so single furrows show.
"""

from __future__ import annotations

import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from PIL import Image, ImageDraw

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import HERE  # noqa: E402

from jaxskin import lockstep, texture, wrinkles  # noqa: E402
from jaxskin.scene import load_scene  # noqa: E402

TILE = 512


def fields(name: str, size: int) -> tuple[np.ndarray, np.ndarray]:
    sc = load_scene(name, [f"texture.size={size}"])
    s = texture.setup(sc.config.texture)
    k, key = sc.config.texture.k_scale, jax.random.key(sc.config.texture.seed)
    hs, _ = wrinkles.height_field(s.mask, s.field1, s.field2,
                                  jnp.asarray(s.tmap.centroids(), jnp.float32), k, key,
                                  radius=wrinkles.window_radius(k), wrap=s.tmap.wrap_x)
    hp, _ = lockstep.height_field(s.mask, s.field1, s.field2, k, key, wrap=s.tmap.wrap_x)
    return np.asarray(hs), np.asarray(hp)


def tile(h: np.ndarray) -> np.ndarray:
    """A TILE² view: the whole field if it fits, else its middle at full resolution."""
    H, W = h.shape
    if H <= TILE and W <= TILE:
        out = np.ones((TILE, TILE), np.float32)
        out[:H, :W] = h
        return out
    y0, x0 = max((H - TILE) // 2, 0), max((W - TILE) // 2, 0)
    out = np.ones((TILE, TILE), np.float32)
    crop = h[y0:y0 + TILE, x0:x0 + TILE]
    out[:crop.shape[0], :crop.shape[1]] = crop
    return out


def main():
    gap, head = 8, 24
    names = ("hand", "arm", "face")
    labels = ("sequential 512x512", "parallel 512x512", "sequential 2048x2048 (middle)",
              "parallel 2048x2048 (middle)")  # PIL's default font has no "²"
    sheet = Image.new("L", (4 * TILE + 3 * gap, len(names) * (TILE + head + gap)), 255)
    draw = ImageDraw.Draw(sheet)
    for row, name in enumerate(names):
        views = [*fields(name, 512), *fields(name, 2048)]
        y = row * (TILE + head + gap)
        for col, (h, label) in enumerate(zip(views, labels, strict=True)):
            x = col * (TILE + gap)
            draw.text((x + 4, y + 6), f"{name}: {label}", fill=0)
            sheet.paste(Image.fromarray((tile(h) * 255).astype(np.uint8)), (x, y + head))
        print(name, flush=True)
    path = HERE / "furrows_side_by_side.png"
    sheet.save(path, optimize=True)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
