"""The furrow height field grown in lockstep: a parallel program of Bando 2001 §3.3.

`wrinkles.height_field` draws one furrow after another. Here `slots` furrows grow at once,
one step each per iteration, in fixed-shape arrays (no data-dependent Python loop), so a
GPU (or the CPU's vector units) does a step of many furrows in one pass. The rules are
the sequential program's — the §5.2 functions, the random turn about the local field,
the stop at the nearest crossing of another furrow of the same pass or of the mesh border
(T-junctions), the f_limit count, the two halves along ±d from the seed, the two passes
merged by minimum — with three changes that make it parallel:

- **seeds in rounds, coarse to fine.** For the paper's "centroids, then every texel"
  (sparse cover first, gaps stuffed after), round r takes one jittered point per cell of a
  grid of `cells[r]` texels, in a scrambled order; a seed is taken when no furrow line is
  yet within f_density/2 of it (the buffer B, read in the owner image at `_RING` points
  around the seed). Round 0's furrows run long over an empty texture, later rounds fill
  the gaps with short ones;
- **a work queue.** Each of the `slots` holds one furrow (its +d half, then its −d half);
  a slot whose furrow ended takes the queue's next seed at the next iteration, so no slot
  waits for the longest furrow; when a round's queue is used up the next round's is made
  at once (from the furrows drawn so far). Ids are given in the order seeds are taken
  (the priority: where two furrows draw the same texel the earlier keeps it);
- **stops see the furrows drawn up to the previous iteration.** Two furrows that meet in
  the same iteration both see each other one step later (a texel's overlap, then a T).

Each step draws its segment (box-filtered, as the sequential program does) into a window
along it (`_band`: columns or rows along the segment's major axis, a few texels across)
with one flat scatter-min into the image and one into the owner image (the furrow id per
texel, which the stop rule reads). The random turns come from an integer hash of (furrow,
half, step), not threefry (as costly as the rest of a step). Not texel for texel the sequential
program, but its character: `benchmarks/bench_wrinkles.py` and `tests/test_lockstep.py`
compare coverage, orientation histograms, T-junctions and furrow lengths.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from .wrinkles import END_BORDER, END_FURROW, END_LIMIT, END_ZERO, MAX_STEPS, FurrowRecord, furrow

__all__ = ["cells_for", "height_field", "slots_for"]

_NONE = 2**30  # the owner of an undrawn texel (owner ids are min-scattered: earlier wins)


def _ring_points() -> np.ndarray:
    """Points of the unit disc (centre, then rings at 1/3, 2/3 and 1) where B is read."""
    pts = [(0.0, 0.0)]
    for frac, n in ((1 / 3, 8), (2 / 3, 16), (1.0, 24)):
        a = 2 * np.pi * (np.arange(n) + 0.5 * (n % 2)) / n
        pts += list(zip(frac * np.cos(a), frac * np.sin(a), strict=True))
    return np.asarray(pts, np.float32)


_RING = _ring_points()


def cells_for(k_scale: float) -> tuple[int, ...]:
    """The seed grid of each round, in texels: coarse (the paper's centroids: long furrows
    over an empty texture) to fine (about half the furrow spacing at |d| = 1)."""
    fine = max(2, int(round(3.0 * k_scale)))
    return (fine * 16, fine * 4, fine * 2, fine)


def slots_for(height: int, width: int) -> int:
    """Furrows in flight: one per 4096 texels (64 at 512², 1024 at 2048²), so those
    growing at once are far apart compared with the furrow spacing: more cut each other's
    long furrows short (the 90th percentile of lengths falls by a third at one per 2048)."""
    return int(np.clip(height * width // 4096, 32, 8192))


def _hash(v):
    """A 32-bit integer mix (the "lowbias32" hash, C. Wellons), elementwise on uint32."""
    v = v ^ (v >> 16)
    v = v * jnp.uint32(0x7FEB352D)
    v = v ^ (v >> 15)
    v = v * jnp.uint32(0x846CA68B)
    return v ^ (v >> 16)


def _uniform(v):
    """uint32 → float32 uniform in [0, 1) (the top 24 bits)."""
    return (v >> 8).astype(jnp.float32) * (1.0 / (1 << 24))


def _scramble(j, count: int):
    """A fixed permutation of `0 … count − 1` (count <= 2²⁴, an 8192² texture's 2-texel
    cells): j·p mod count with p coprime to count near 0.618·count, four bits of p at a
    time so that uint32 never overflows."""
    p = max(int(0.6180339887 * count), 1)
    while math.gcd(p, count) != 1:
        p += 1
    j = j.astype(jnp.uint32)
    acc = jnp.zeros_like(j)
    for shift in range(20, -1, -4):
        acc = (acc * 16 + j * ((p >> shift) & 15)) % count
    return acc.astype(jnp.int32)


def _band(k_scale: float) -> tuple[int, int]:
    """A step's paint window: `(A, b)`, A texels along the segment's major axis (its length
    and a band's half-width past either end) by 2b + 1 across it (the half-width over the
    cosine of at most 45°, and half a texel)."""
    half = k_scale * 2.0 / 2 + 0.5  # the widest band's half-width (f_width at |d| = 2)
    return (int(math.ceil(6.0 * k_scale)) + 2 * int(math.ceil(half)) + 2,
            int(math.ceil(half * math.sqrt(2.0) + 0.5)))


def height_field(mask, field1, field2, k_scale: float, key, records: int = 1,
                 wrap: bool = False, slots: int = 0, cells: tuple[int, ...] = ()):
    """The wrinkle height field before noise, grown in lockstep (see the module doc).

    **Arguments:**

    - `mask (H, W)` bool: texels on the mesh.
    - `field1`, `field2 (H, W, 2)`: the fields in texture space (pixel frame, |d| in [0, 2]).
    - `k_scale` (static): the paper's scale.
    - `key`: a `jax.random` key.
    - `records`: how many furrows per pass to record in the returned `FurrowRecord`.
    - `wrap`: x is periodic (a cylinder's texture): furrows cross the seam.
    - `slots`: furrows grown at once (0: `slots_for(H, W)`).
    - `cells`: the seed grid per round (empty: `cells_for(k_scale)`).

    **Returns:** `(h (H, W) float32 in [0, 1] with 1 off the mesh, FurrowRecord)`, the record
    as `wrinkles.height_field`'s (furrow ids in the order their seeds were taken). An
    int32/float32 program, the same under a caller's float64 (`jax.enable_x64`).
    """
    with jax.enable_x64(False):
        return _height_field(mask, field1, field2, k_scale, key, records, wrap, slots, cells)


@functools.partial(jax.jit, static_argnames=("k_scale", "records", "wrap", "slots", "cells"))
def _height_field(mask, field1, field2, k_scale, key, records, wrap, slots, cells):
    H, W = mask.shape
    slots = slots or slots_for(H, W)
    cells = cells or cells_for(k_scale)
    run = functools.partial(_pass, mask, k_scale=k_scale, records=max(records, 1), wrap=wrap,
                            slots=slots, cells=cells)
    fields = (field1.astype(jnp.float32).reshape(-1, 2), field2.astype(jnp.float32).reshape(-1, 2))
    # The two passes one after the other, one compiled body (a loop over the pass; its
    # field read where needed rather than the two stacked: a copy of both, 64 MB at 2048²).
    shapes = jax.eval_shape(lambda: run(fields, 0, key))

    def one(p, c):
        h, rec = c
        img, r = run(fields, p, jax.random.fold_in(key, p + 1))
        rec = jax.tree.map(lambda a, b: jax.lax.dynamic_update_index_in_dim(a, b, p, 0), rec, r)
        return jnp.minimum(h, img), rec

    rec = jax.tree.map(lambda a: jnp.zeros((2, *a.shape), a.dtype), shapes[1])
    h, rec = jax.lax.fori_loop(0, 2, one, (jnp.ones(mask.shape, jnp.float32), rec))
    return jnp.where(mask, h, 1.0), rec


def _pass(mask, fields, p, key, *, k_scale, records, wrap, slots, cells):
    H, W = mask.shape
    n = H * W
    inside = mask.reshape(-1)

    def field_at(idx):
        """The pass's field at flat texels `idx` (0 where idx = n)."""
        return jnp.where(p == 0, read(fields[0], idx, 0.0), read(fields[1], idx, 0.0))
    A, b = _band(k_scale)
    along, across = (jnp.asarray(a.ravel()) for a in np.meshgrid(
        np.arange(A) - (A - int(math.ceil(6.0 * k_scale))) // 2, np.arange(-b, b + 1),
        indexing="ij"))
    n_samples = 2 * int(math.ceil(6.0 * k_scale))  # <= half a texel apart
    samples = jnp.arange(1, n_samples + 1, dtype=jnp.float32) / n_samples
    ring = jnp.asarray(_RING)

    def flat(ix, iy, ok=True):
        """Flat index of texels (ix, iy), wrapped in x if `wrap`; n (dropped) where off the
        texture or not `ok`."""
        ix = ix % W if wrap else ix
        good = (ix >= 0) & (ix < W) & (iy >= 0) & (iy < H) & ok
        return jnp.where(good, iy * W + ix, n)

    def read(a, idx, fill):
        good = (idx < n).reshape(idx.shape + (1,) * (a.ndim - 1))
        return jnp.where(good, a[jnp.minimum(idx, n - 1)], fill)

    def free(owner, pts, ring=ring):
        """Seeds `(K, 2)` on the mesh with no furrow line within f_density/2 (not in B): no
        drawn texel (those lie within f_width/2 + 1/2 of a line) at the `ring` points of a
        disc of radius f_density/2 − f_width/2 − 1/2."""
        ip = jnp.floor(pts).astype(jnp.int32)
        here = flat(ip[:, 0], ip[:, 1])
        x = jnp.linalg.norm(field_at(here), axis=-1)
        _, _, density, width, _, _ = furrow(x, k_scale)
        # Materialised: fused into the reads below, this was recomputed per ring point.
        pts, rho = jax.lax.optimization_barrier((pts, jnp.maximum(density / 2 - width / 2 - 0.5,
                                                                    0.0)))
        around = jnp.floor(pts[:, None] + rho[:, None, None] * ring).astype(jnp.int32)
        taken = read(owner, flat(around[..., 0], around[..., 1]), _NONE) < _NONE
        return read(inside, here, False) & ~jnp.any(taken, axis=1)

    salt = jax.random.bits(key, (), jnp.uint32)

    def turn(fid, half, s):
        """Uniform in [0, 1) per (furrow, half, step): a hash (threefry per step costs as
        much as the rest of the step)."""
        return _uniform(_hash(salt ^ _hash(fid.astype(jnp.uint32) * 64 + half * 32 + s)))

    def step(c):
        (img, owner, rec, rnd, queue, n_queue, head, next_id, alive, fid, half, seed, P, s,
         n_limit, length) = c
        # 1. When a round's queue is used up, the next round's is made (from the furrows
        # drawn so far; those still growing finish meanwhile). Idle slots take the next
        # seeds of the queue, in order, if still free.
        more = (head >= n_queue) & (rnd + 1 < len(cells))
        rnd = rnd + more
        queue, n_queue, head = jax.lax.cond(
            more, lambda: (*jax.lax.switch(rnd, branches, owner, salt + rnd.astype(jnp.uint32)),
                           jnp.int32(0)), lambda: (queue, n_queue, head))
        idle = ~alive
        pos = head + jnp.cumsum(idle) - 1
        take = idle & (pos < n_queue)
        cand = queue[jnp.clip(pos, 0, queue.shape[0] - 1)]
        ok = take & free(owner, cand)
        new_id = next_id + jnp.cumsum(ok) - 1
        head = head + jnp.sum(take)
        next_id = next_id + jnp.sum(ok)
        fid = jnp.where(ok, new_id, fid)
        seed = jnp.where(ok[:, None], cand, seed)
        P = jnp.where(ok[:, None], cand, P)
        half = jnp.where(ok, 0, half)
        s = jnp.where(ok, 0, s)
        n_limit = jnp.where(ok, 2**30, n_limit)
        length = jnp.where(ok, 0.0, length)
        alive = alive | ok
        # 2. Every live furrow moves one step (the sequential program's step, vectorised).
        ip = jnp.floor(P).astype(jnp.int32)
        at = flat(jnp.clip(ip[:, 0], 0, W - 1), jnp.clip(ip[:, 1], 0, H - 1))
        d = jnp.where(half[:, None] == 0, 1.0, -1.0) * field_at(at)
        x = jnp.linalg.norm(d, axis=-1)
        zero = x < 1e-6
        angle, f_len, _, width, depth, limit = furrow(x, k_scale)
        theta = angle * (turn(fid, half.astype(jnp.uint32), s.astype(jnp.uint32)) - 0.5)
        unit = d / jnp.where(zero, 1.0, x)[:, None]
        co, sn = jnp.cos(theta), jnp.sin(theta)
        direction = jnp.stack([co * unit[:, 0] - sn * unit[:, 1],
                               sn * unit[:, 0] + co * unit[:, 1]], -1)
        Q0 = P + f_len[:, None] * direction
        pts = P[:, None] + samples[None, :, None] * (Q0 - P)[:, None]
        pi = jnp.floor(pts).astype(jnp.int32)
        idx = flat(pi[..., 0], pi[..., 1])
        who = read(owner, idx, _NONE)
        hit_furrow = (who < _NONE) & (who != fid[:, None])
        hit = ~read(inside, idx, False) | hit_furrow
        any_hit = jnp.any(hit, axis=1)
        k = jnp.argmax(hit, axis=1)
        Q = jnp.where(any_hit[:, None], jnp.take_along_axis(pts, k[:, None, None], 1)[:, 0], Q0)
        draw = alive & ~zero
        # 3. Draw the segment in its window: one scatter-min into the image, one into owner.
        # The window: columns (or rows, whichever the segment runs along more) from one end,
        # 2b + 1 texels about the segment's line at each.
        v = Q - P
        major = (jnp.abs(v[:, 1]) > jnp.abs(v[:, 0])).astype(jnp.int32)[:, None]  # 0: x
        pm = jnp.where(major == 0, P[:, 0:1], P[:, 1:2])
        pn = jnp.where(major == 0, P[:, 1:2], P[:, 0:1])
        vm = jnp.where(major == 0, v[:, 0:1], v[:, 1:2])
        vn = jnp.where(major == 0, v[:, 1:2], v[:, 0:1])
        lo = jnp.floor(jnp.minimum(pm, pm + vm)).astype(jnp.int32)
        im = lo + along  # texel along the major axis
        cm = im.astype(jnp.float32) + 0.5
        line = pn + vn * jnp.clip((cm - pm) / jnp.where(vm == 0, 1.0, vm), 0.0, 1.0)
        inn = jnp.floor(line).astype(jnp.int32) + across
        ix, iy = jnp.where(major == 0, im, inn), jnp.where(major == 0, inn, im)
        tx = ix.astype(jnp.float32) + 0.5 - P[:, 0:1]
        ty = iy.astype(jnp.float32) + 0.5 - P[:, 1:2]
        t = jnp.clip((tx * v[:, 0:1] + ty * v[:, 1:2])
                     / jnp.maximum(jnp.sum(v * v, -1), 1e-12)[:, None], 0.0, 1.0)
        dx, dy = tx - t * v[:, 0:1], ty - t * v[:, 1:2]
        dist = jnp.sqrt(dx * dx + dy * dy)  # not hypot: 3x slower, and no overflow here
        cover = jnp.clip(width[:, None] / 2 + 0.5 - dist, 0.0, 1.0)
        widx = flat(ix, iy, draw[:, None] & (cover > 0))
        img = img.at[widx].min(1.0 - depth[:, None] * cover, mode="drop")
        owner = owner.at[widx].min(jnp.broadcast_to(fid[:, None], widx.shape), mode="drop")
        # 4. Stop, as the sequential program does; a stopped +d half restarts as the −d half.
        stop = alive & (zero | any_hit | (n_limit == 0) | (s + 1 >= MAX_STEPS))
        reason = jnp.where(zero, END_ZERO, jnp.where(any_hit, jnp.where(
            jnp.take_along_axis(hit_furrow, k[:, None], 1)[:, 0], END_FURROW, END_BORDER),
            END_LIMIT))
        length = length + jnp.where(draw, jnp.sqrt(jnp.sum(v * v, -1)), 0.0)
        P = jnp.where(draw[:, None], Q, P)
        if wrap:
            P = P.at[:, 0].set(jnp.mod(P[:, 0], W))
        s = s + 1
        slot = jnp.where(stop & (fid < records), fid, records)  # records: dropped
        seed_r, end_r, reason_r, seg_r, len_r = rec
        rec = (seed_r.at[slot].set(seed, mode="drop"),
               end_r.at[slot, half].set(P, mode="drop"),
               reason_r.at[slot, half].set(reason, mode="drop"),
               seg_r.at[slot, half].set(s, mode="drop"),
               len_r.at[slot, half].set(length, mode="drop"))
        again = stop & (half == 0)
        alive = alive & ~(stop & (half == 1))
        half = jnp.where(again, 1, half)
        P = jnp.where(again[:, None], seed, P)
        s = jnp.where(again, 0, s)
        n_limit = jnp.where(again, 2**30, jnp.minimum(n_limit, limit) - 1)
        length = jnp.where(again, 0.0, length)
        return (img, owner, rec, rnd, queue, n_queue, head, next_id, alive, fid, half, seed, P,
                s, n_limit, length)

    img = jnp.ones(n, jnp.float32)
    owner = jnp.full(n, _NONE, jnp.int32)
    rec = (jnp.zeros((records, 2), jnp.float32), jnp.zeros((records, 2, 2), jnp.float32),
           jnp.full((records, 2), -1, jnp.int32), jnp.zeros((records, 2), jnp.int32),
           jnp.zeros((records, 2), jnp.float32))
    zeros = jnp.zeros(slots, jnp.int32)
    state = (jnp.zeros(slots, bool), zeros, zeros, jnp.zeros((slots, 2), jnp.float32),
             jnp.zeros((slots, 2), jnp.float32), zeros, zeros, jnp.zeros(slots, jnp.float32))
    # A round's queue: one jittered point per cell, the cells in a scrambled order (so that
    # the furrows growing at once are far apart), those free now, at most `cap` of them.
    counts = [-(-W // c) * -(-H // c) for c in cells]
    cap = max(max(counts[:-1], default=1), counts[-1] // 2)

    def queue_of(cell, count, owner, rkey):
        nx = -(-W // cell)
        j = _scramble(jnp.arange(count, dtype=jnp.int32), count)
        corner = jnp.stack([j % nx, j // nx], -1).astype(jnp.float32) * cell
        jitter = _uniform(_hash(rkey ^ _hash(jnp.arange(2 * count, dtype=jnp.uint32))))
        jitter = jitter.reshape(count, 2)
        pts = jnp.minimum(corner + jitter * cell, jnp.asarray([W, H], jnp.float32) - 0.5)
        # A cheap first sieve (a third of the ring's points); a seed is read again in full
        # when a slot takes it.
        ok = free(owner, pts, ring[::3])
        (keep,) = jnp.nonzero(ok, size=cap, fill_value=0)
        return pts[keep], jnp.minimum(jnp.sum(ok), cap)

    branches = [functools.partial(queue_of, c, n) for c, n in zip(cells, counts, strict=True)]

    queue, n_queue = branches[0](owner, salt)
    c = (img, owner, rec, jnp.int32(0), queue, n_queue, jnp.int32(0), jnp.int32(0), *state)
    c = jax.lax.while_loop(
        lambda c: (c[6] < c[5]) | (c[3] + 1 < len(cells)) | jnp.any(c[8]), step, c)
    img, owner, rec, next_id = c[0], c[1], c[2], c[7]
    owner = jnp.where(owner < _NONE, owner, -1).reshape(H, W)
    return img.reshape(H, W), FurrowRecord(*rec, count=next_id, owner=owner)
