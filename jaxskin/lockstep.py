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
from typing import NamedTuple

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


class _Pass(NamedTuple):
    """One pass's constants, shared by its steps: the texture's size `H, W` and texel count
    `n`, the pass `p` (its field in `fields`), the flat mesh mask `inside`, a step's paint
    window (`along`, `across`), a segment's sample points, the `ring` where B is read, the
    pass's random `salt`, and the seed rounds (`cells`, the `counts` of their cells, the
    queue's `cap`)."""

    H: int
    W: int
    n: int
    wrap: bool
    k_scale: float
    records: int
    cells: tuple
    counts: tuple
    cap: int
    p: jax.Array
    inside: jax.Array
    fields: tuple
    along: jax.Array
    across: jax.Array
    samples: jax.Array
    ring: jax.Array
    salt: jax.Array


class _Slots(NamedTuple):
    """Per slot: whether a furrow grows there, its id, which half (0: +d, 1: −d), its seed,
    its point P, the steps `s` of this half, N_limit and the length drawn."""

    alive: jax.Array
    fid: jax.Array
    half: jax.Array
    seed: jax.Array
    P: jax.Array
    s: jax.Array
    n_limit: jax.Array
    length: jax.Array


def _pass(mask, fields, p, key, *, k_scale, records, wrap, slots, cells):
    """One field's image (§3.3 field steps 1–3, or 5–7): `_step` until every round's queue
    is used up and no furrow grows."""
    H, W = mask.shape
    n = H * W
    inside = mask.reshape(-1)
    A, b = _band(k_scale)
    along, across = (jnp.asarray(a.ravel()) for a in np.meshgrid(
        np.arange(A) - (A - int(math.ceil(6.0 * k_scale))) // 2, np.arange(-b, b + 1),
        indexing="ij"))
    n_samples = 2 * int(math.ceil(6.0 * k_scale))  # <= half a texel apart
    samples = jnp.arange(1, n_samples + 1, dtype=jnp.float32) / n_samples
    ring = jnp.asarray(_RING)
    salt = jax.random.bits(key, (), jnp.uint32)

    img = jnp.ones(n, jnp.float32)
    owner = jnp.full(n, _NONE, jnp.int32)
    rec = (jnp.zeros((records, 2), jnp.float32), jnp.zeros((records, 2, 2), jnp.float32),
           jnp.full((records, 2), -1, jnp.int32), jnp.zeros((records, 2), jnp.int32),
           jnp.zeros((records, 2), jnp.float32))
    zeros = jnp.zeros(slots, jnp.int32)
    state = _Slots(jnp.zeros(slots, bool), zeros, zeros, jnp.zeros((slots, 2), jnp.float32),
                   jnp.zeros((slots, 2), jnp.float32), zeros, zeros,
                   jnp.zeros(slots, jnp.float32))
    # A round's queue: one jittered point per cell, the cells in a scrambled order (so that
    # the furrows growing at once are far apart), those free now, at most `cap` of them.
    counts = tuple(-(-W // c) * -(-H // c) for c in cells)
    cap = max(max(counts[:-1], default=1), counts[-1] // 2)
    t = _Pass(H, W, n, wrap, k_scale, records, cells, counts, cap, p, inside, fields, along,
              across, samples, ring, salt)

    queue, n_queue = _queue_of(t, cells[0], counts[0], owner, salt)
    c = (img, owner, rec, jnp.int32(0), queue, n_queue, jnp.int32(0), jnp.int32(0), state)
    c = jax.lax.while_loop(
        lambda c: (c[6] < c[5]) | (c[3] + 1 < len(cells)) | jnp.any(c[8].alive),
        functools.partial(_step, t), c)
    img, owner, rec, next_id = c[0], c[1], c[2], c[7]
    owner = jnp.where(owner < _NONE, owner, -1).reshape(H, W)
    return img.reshape(H, W), FurrowRecord(*rec, count=next_id, owner=owner)


def _step(t: _Pass, c):
    """One iteration: idle slots take seeds, then every live furrow grows one segment, draws
    it and stops or goes on (§3.3 furrow steps 1–6, all slots at once)."""
    img, owner, rec, rnd, queue, n_queue, head, next_id, sl = c
    rnd, queue, n_queue, head = _next_round(t, owner, rnd, queue, n_queue, head)
    head, next_id, sl = _seed(t, owner, queue, n_queue, head, next_id, sl)
    direction, zero, f_len, width, depth, limit = _turn(t, sl)
    Q, any_hit, hit_furrow, k = _grow(t, owner, sl.P, direction, f_len, sl.fid)
    draw = sl.alive & ~zero
    img, owner, v = _draw(t, img, owner, sl.P, Q, draw, width, depth, sl.fid)
    stop, reason = _stop(sl, zero, any_hit, hit_furrow, k)
    # Step 6's "P ← Q" (taken one turn back on a cylinder), and the length drawn.
    length = sl.length + jnp.where(draw, jnp.sqrt(jnp.sum(v * v, -1)), 0.0)
    P = jnp.where(draw[:, None], Q, sl.P)
    if t.wrap:
        P = P.at[:, 0].set(jnp.mod(P[:, 0], t.W))
    sl = sl._replace(P=P, s=sl.s + 1, length=length)
    rec = _record(rec, t.records, sl, stop, reason)
    sl = _turn_back(sl, stop, limit)
    return (img, owner, rec, rnd, queue, n_queue, head, next_id, sl)


def _next_round(t: _Pass, owner, rnd, queue, n_queue, head):
    """Seed: when a round's queue is used up, the next round's is made (from the furrows
    drawn so far; those still growing finish meanwhile)."""
    more = (head >= n_queue) & (rnd + 1 < len(t.cells))
    rnd = rnd + more
    branches = [functools.partial(_queue_of, t, c, n)
                for c, n in zip(t.cells, t.counts, strict=True)]
    queue, n_queue, head = jax.lax.cond(
        more, lambda: (*jax.lax.switch(rnd, branches, owner, t.salt + rnd.astype(jnp.uint32)),
                       jnp.int32(0)), lambda: (queue, n_queue, head))
    return rnd, queue, n_queue, head


def _queue_of(t: _Pass, cell, count, owner, rkey):
    """Seed: a round's queue, one jittered point per cell of `cell` texels, the cells in a
    scrambled order, those free now (at most `cap`). Returns `(points, how many)`."""
    W, H = t.W, t.H
    nx = -(-W // cell)
    j = _scramble(jnp.arange(count, dtype=jnp.int32), count)
    corner = jnp.stack([j % nx, j // nx], -1).astype(jnp.float32) * cell
    jitter = _uniform(_hash(rkey ^ _hash(jnp.arange(2 * count, dtype=jnp.uint32))))
    jitter = jitter.reshape(count, 2)
    pts = jnp.minimum(corner + jitter * cell, jnp.asarray([W, H], jnp.float32) - 0.5)
    # A cheap first sieve (a third of the ring's points); a seed is read again in full
    # when a slot takes it.
    ok = _free(t, owner, pts, t.ring[::3])
    (keep,) = jnp.nonzero(ok, size=t.cap, fill_value=0)
    return pts[keep], jnp.minimum(jnp.sum(ok), t.cap)


def _seed(t: _Pass, owner, queue, n_queue, head, next_id, sl: _Slots):
    """Seed (§3.3 field steps 2–3): idle slots take the queue's next seeds, in order, those
    still free (not in B) starting a furrow's +d half with N_limit = ∞. Returns `(head,
    next_id, slots)`."""
    alive, fid, half, seed, P, s, n_limit, length = sl
    idle = ~alive
    pos = head + jnp.cumsum(idle) - 1
    take = idle & (pos < n_queue)
    cand = queue[jnp.clip(pos, 0, queue.shape[0] - 1)]
    ok = take & _free(t, owner, cand, t.ring)
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
    return head, next_id, _Slots(alive, fid, half, seed, P, s, n_limit, length)


def _turn(t: _Pass, sl: _Slots):
    """Grow, §3.3 furrow steps 1–2 (each slot): d at P (−d on the second half), the §5.2
    functions of |d|, and d turned by a random angle in ±f_angle/2. Returns `(direction,
    zero, f_length, f_width, f_depth, f_limit)`, `zero` where |d| = 0."""
    W, H = t.W, t.H
    ip = jnp.floor(sl.P).astype(jnp.int32)
    at = _flat(t, jnp.clip(ip[:, 0], 0, W - 1), jnp.clip(ip[:, 1], 0, H - 1))
    d = jnp.where(sl.half[:, None] == 0, 1.0, -1.0) * _field_at(t, at)
    x = jnp.linalg.norm(d, axis=-1)
    zero = x < 1e-6
    angle, f_len, _, width, depth, limit = furrow(x, t.k_scale)
    theta = angle * (_random_turn(t, sl.fid, sl.half.astype(jnp.uint32),
                                  sl.s.astype(jnp.uint32)) - 0.5)
    unit = d / jnp.where(zero, 1.0, x)[:, None]
    co, sn = jnp.cos(theta), jnp.sin(theta)
    direction = jnp.stack([co * unit[:, 0] - sn * unit[:, 1],
                           sn * unit[:, 0] + co * unit[:, 1]], -1)
    return direction, zero, f_len, width, depth, limit


def _grow(t: _Pass, owner, P, direction, f_len, fid):
    """Grow, §3.3 furrow step 3 (each slot): move f_length from P; Q is the reached point or
    the nearest crossing of the mesh border or of another furrow drawn up to the previous
    iteration. Returns `(Q, any_hit, hit_furrow, k)` as `wrinkles`' step does."""
    Q0 = P + f_len[:, None] * direction
    pts = P[:, None] + t.samples[None, :, None] * (Q0 - P)[:, None]
    pi = jnp.floor(pts).astype(jnp.int32)
    idx = _flat(t, pi[..., 0], pi[..., 1])
    who = _read(t, owner, idx, _NONE)
    hit_furrow = (who < _NONE) & (who != fid[:, None])
    hit = ~_read(t, t.inside, idx, False) | hit_furrow
    any_hit = jnp.any(hit, axis=1)
    k = jnp.argmax(hit, axis=1)
    Q = jnp.where(any_hit[:, None], jnp.take_along_axis(pts, k[:, None, None], 1)[:, 0], Q0)
    return Q, any_hit, hit_furrow, k


def _draw(t: _Pass, img, owner, P, Q, draw, width, depth, fid):
    """Draw, §3.3 furrow steps 4–5 (each slot): the segment P–Q f_width wide, f_depth deep,
    in its window, with one scatter-min into the image and one into the owner image (which
    the stop rule and the seeds' B test read). The window: columns (or rows, whichever the
    segment runs along more) from one end, 2b + 1 texels about the segment's line at each.
    Returns `(img, owner, Q − P)`."""
    along, across = t.along, t.across
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
    tt = jnp.clip((tx * v[:, 0:1] + ty * v[:, 1:2])
                  / jnp.maximum(jnp.sum(v * v, -1), 1e-12)[:, None], 0.0, 1.0)
    dx, dy = tx - tt * v[:, 0:1], ty - tt * v[:, 1:2]
    dist = jnp.sqrt(dx * dx + dy * dy)  # not hypot: 3x slower, and no overflow here
    cover = jnp.clip(width[:, None] / 2 + 0.5 - dist, 0.0, 1.0)
    widx = _flat(t, ix, iy, draw[:, None] & (cover > 0))
    img = img.at[widx].min(1.0 - depth[:, None] * cover, mode="drop")
    owner = owner.at[widx].min(jnp.broadcast_to(fid[:, None], widx.shape), mode="drop")
    return img, owner, v


def _stop(sl: _Slots, zero, any_hit, hit_furrow, k):
    """Stop, §3.3 furrow step 6 (each slot), as the sequential program does: at N_limit = 0,
    where step 3 met something, where |d| = 0, or after `MAX_STEPS`. Returns `(stop,
    reason)`."""
    stop = sl.alive & (zero | any_hit | (sl.n_limit == 0) | (sl.s + 1 >= MAX_STEPS))
    reason = jnp.where(zero, END_ZERO, jnp.where(any_hit, jnp.where(
        jnp.take_along_axis(hit_furrow, k[:, None], 1)[:, 0], END_FURROW, END_BORDER),
        END_LIMIT))
    return stop, reason


def _record(rec, records, sl: _Slots, stop, reason):
    """The first `records` furrows' seed and, for each half that stopped, its end, reason,
    segments and length."""
    slot = jnp.where(stop & (sl.fid < records), sl.fid, records)  # records: dropped
    seed_r, end_r, reason_r, seg_r, len_r = rec
    return (seed_r.at[slot].set(sl.seed, mode="drop"),
            end_r.at[slot, sl.half].set(sl.P, mode="drop"),
            reason_r.at[slot, sl.half].set(reason, mode="drop"),
            seg_r.at[slot, sl.half].set(sl.s, mode="drop"),
            len_r.at[slot, sl.half].set(sl.length, mode="drop"))


def _turn_back(sl: _Slots, stop, limit):
    """Stop or go on (§3.3 furrow step 6): a stopped +d half restarts from its seed as the
    −d half, a stopped −d half frees its slot; the others go on with N_limit ←
    min(N_limit, f_limit) − 1."""
    alive, fid, half, seed, P, s, n_limit, length = sl
    again = stop & (half == 0)
    alive = alive & ~(stop & (half == 1))
    half = jnp.where(again, 1, half)
    P = jnp.where(again[:, None], seed, P)
    s = jnp.where(again, 0, s)
    n_limit = jnp.where(again, 2**30, jnp.minimum(n_limit, limit) - 1)
    length = jnp.where(again, 0.0, length)
    return _Slots(alive, fid, half, seed, P, s, n_limit, length)


def _field_at(t: _Pass, idx):
    """The pass's field at flat texels `idx` (0 where idx = n)."""
    return jnp.where(t.p == 0, _read(t, t.fields[0], idx, 0.0), _read(t, t.fields[1], idx, 0.0))


def _flat(t: _Pass, ix, iy, ok=True):
    """Flat index of texels (ix, iy), wrapped in x if `wrap`; n (dropped) where off the
    texture or not `ok`."""
    W, H, n = t.W, t.H, t.n
    ix = ix % W if t.wrap else ix
    good = (ix >= 0) & (ix < W) & (iy >= 0) & (iy < H) & ok
    return jnp.where(good, iy * W + ix, n)


def _read(t: _Pass, a, idx, fill):
    """`a` at flat texels `idx`, `fill` where idx = n (off the texture)."""
    n = t.n
    good = (idx < n).reshape(idx.shape + (1,) * (a.ndim - 1))
    return jnp.where(good, a[jnp.minimum(idx, n - 1)], fill)


def _free(t: _Pass, owner, pts, ring):
    """Seeds `(K, 2)` on the mesh with no furrow line within f_density/2 (not in B): no
    drawn texel (those lie within f_width/2 + 1/2 of a line) at the `ring` points of a
    disc of radius f_density/2 − f_width/2 − 1/2."""
    ip = jnp.floor(pts).astype(jnp.int32)
    here = _flat(t, ip[:, 0], ip[:, 1])
    x = jnp.linalg.norm(_field_at(t, here), axis=-1)
    _, _, density, width, _, _ = furrow(x, t.k_scale)
    # Materialised: fused into the reads below, this was recomputed per ring point.
    pts, rho = jax.lax.optimization_barrier((pts, jnp.maximum(density / 2 - width / 2 - 0.5,
                                                                0.0)))
    around = jnp.floor(pts[:, None] + rho[:, None, None] * ring).astype(jnp.int32)
    taken = _read(t, owner, _flat(t, around[..., 0], around[..., 1]), _NONE) < _NONE
    return _read(t, t.inside, here, False) & ~jnp.any(taken, axis=1)


def _random_turn(t: _Pass, fid, half, s):
    """Uniform in [0, 1) per (furrow, half, step): a hash (threefry per step costs as
    much as the rest of the step)."""
    return _uniform(_hash(t.salt ^ _hash(fid.astype(jnp.uint32) * 64 + half * 32 + s)))
