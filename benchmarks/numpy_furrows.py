"""A straightforward NumPy transcription of the furrow algorithm (the benchmark baseline).

The same algorithm as `jaxskin.wrinkles.height_field`, written the way one would first
write it: a Python loop over every seed (centroids, then every texel, checking B), a Python
loop over the steps of each furrow, NumPy on the window each step touches. It draws the same random
turns (a table made from the same key chain), so the two can be compared texel by texel.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from jaxskin import wrinkles


def uniform_table(key, furrows: int) -> np.ndarray:
    """U[pass, furrow, half, step]: the turns `height_field` draws, for the first furrows."""

    def one(p, f, h, s):
        k = jax.random.fold_in(jax.random.fold_in(jax.random.fold_in(
            jax.random.fold_in(key, p + 1), f), h), s)
        return jax.random.uniform(k)

    grid = jnp.meshgrid(jnp.arange(2), jnp.arange(furrows), jnp.arange(2),
                        jnp.arange(wrinkles.MAX_STEPS), indexing="ij")
    return np.asarray(jax.jit(jax.vmap(one))(*(g.ravel() for g in grid))).reshape(
        2, furrows, 2, wrinkles.MAX_STEPS)


def furrow_functions(x, k):
    x = min(max(x, 0.0), 2.0)
    return (1 - 0.4 * x, k * (4 + x), k * (1 + 6 * x), k * x, 0.25 * x * x,
            int(math.floor(30 - 10 * x)))


def height_field(mask, field1, field2, centroids, k_scale, key, radius, table_size=8192):
    mask = np.asarray(mask, bool)
    H, W = mask.shape
    U = uniform_table(key, table_size)
    images = []
    for p, field in enumerate((np.asarray(field1, np.float32), np.asarray(field2, np.float32))):
        img = np.ones((H, W), np.float32)
        owner = np.full((H, W), -1, np.int64)
        B = np.zeros((H, W), bool)
        fid = 0
        seeds = [tuple(c) for c in np.asarray(centroids, np.float32)]
        seeds += [(j + 0.5, i + 0.5) for i in range(H) for j in range(W)]
        for sx, sy in seeds:
            ix, iy = int(math.floor(sx)), int(math.floor(sy))
            if not (0 <= ix < W and 0 <= iy < H) or not mask[iy, ix] or B[iy, ix]:
                continue
            for half, sign in enumerate((1.0, -1.0)):
                _draw_half(img, owner, B, mask, field, np.array([sx, sy], np.float32), sign,
                           fid, U[p, fid, half], k_scale, radius)
            fid += 1
        images.append(img)
    return np.where(mask, np.minimum(*images), 1.0)


def _draw_half(img, owner, B, mask, field, P, sign, fid, turns, k_scale, R):
    H, W = mask.shape
    n_samples = 2 * int(math.ceil(6.0 * 2))
    n_limit = 2**30
    for step in range(wrinkles.MAX_STEPS):
        ix = min(max(int(math.floor(P[0])), 0), W - 1)
        iy = min(max(int(math.floor(P[1])), 0), H - 1)
        d = sign * field[iy, ix]
        x = float(np.hypot(d[0], d[1]))
        if x < 1e-6:
            return
        angle, f_len, density, width, depth, limit = furrow_functions(x, k_scale)
        theta = angle * (turns[step] - 0.5)
        u = d / x
        c, s = math.cos(theta), math.sin(theta)
        Q0 = P + f_len * np.array([c * u[0] - s * u[1], s * u[0] + c * u[1]], np.float32)
        Q, hit = Q0, False
        for k in range(1, n_samples + 1):
            q = P + (k / n_samples) * (Q0 - P)
            qx, qy = int(math.floor(q[0])), int(math.floor(q[1]))
            inside = 0 <= qx < W and 0 <= qy < H and mask[qy, qx]
            other = inside and owner[qy, qx] >= 0 and owner[qy, qx] != fid
            if not inside or other:
                Q, hit = q, True
                break
        # Draw the segment on its window (NumPy over the window, clipped to the image).
        cx, cy = (int(math.floor(v)) for v in (P + Q) / 2)
        i0, i1, j0, j1 = max(cy - R, 0), min(cy + R + 1, H), max(cx - R, 0), min(cx + R + 1, W)
        v = Q - P
        tx = (np.arange(j0, j1, dtype=np.float32) + 0.5 - P[0])[None, :]
        ty = (np.arange(i0, i1, dtype=np.float32) + 0.5 - P[1])[:, None]
        t = np.clip((tx * v[0] + ty * v[1]) / max(float(v @ v), 1e-12), 0.0, 1.0)
        dist = np.hypot(tx - t * v[0], ty - t * v[1])
        cover = np.clip(width / 2 + 0.5 - dist, 0.0, 1.0)
        img[i0:i1, j0:j1] = np.minimum(img[i0:i1, j0:j1], 1.0 - depth * cover)
        own = owner[i0:i1, j0:j1]
        own[(cover > 0) & (own < 0)] = fid
        B[i0:i1, j0:j1] |= dist <= density / 2
        P = Q
        if hit or n_limit == 0:
            return
        n_limit = min(n_limit, limit) - 1
