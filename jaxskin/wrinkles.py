"""The furrow height field (Bando 2001 §3.3, functions of §5.2), jitted.

For each field (F1, then F2 on a fresh image and buffer B), seeds are the triangle
centroids and then every texel centre, in order; from a seed not marked in B a furrow is
drawn along +d and along −d. Each step interpolates d at P, turns it by a random angle,
moves f_length, and stops at the nearest crossing of another furrow of the same pass or
of the mesh border (so furrow ends form T-junctions); it marks B within f_density/2 of the
segment and draws it f_width wide, f_depth deep. The two images merge by minimum; then
h −= r·k_noise. |d| = x in [0, 2], lengths in texels:

    f_angle = 1 − 0.4x (rad)   f_length = k_scale(4 + x)   f_density = k_scale(1 + 6x)
    f_width = k_scale·x        f_depth = 0.25x²            f_limit = ⌊30 − 10x⌋

Choices where the paper is open, made here:

- the turn: each step deviates from the *local field* direction by a uniform random angle
  in [−f_angle/2, f_angle/2] (independent per step, so furrows wiggle about the field but
  never drift or spiral); the paper only says "rotate d by f_angle";
- the height drawn is 1 − f_depth (white = 1 is the unwrinkled surface, the paper's "color
  f_depth" must mean depth below it); lines are box-filtered (coverage of a line of width
  f_width, clipped to [0, 1]), so narrow furrows still leave a trace;
- "other furrows" are the texels drawn by earlier furrows of the same pass (the two halves
  of one furrow do not stop each other); a step that meets one ends inside its groove;
- seeds: a centroid or texel outside the mesh is skipped; scan order is row by row;
- with the cylindrical projection s is periodic: a furrow runs on across the seam (its
  points are read and its windows drawn one turn over too), so the pattern has no cut.

Deterministic for a given key. The whole field is one jitted program: an outer
`lax.while_loop` over furrows (the next seed is found in O(H + W) from a count of unmarked
texels per row), an inner one over steps, each step touching a (2R + 1)² window.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["END_BORDER", "END_FURROW", "END_LIMIT", "END_ZERO", "FurrowRecord", "add_noise",
           "furrow", "height_field", "noise_field", "to_numpy_record", "window_radius"]

END_LIMIT, END_FURROW, END_BORDER, END_ZERO = 0, 1, 2, 3
MAX_STEPS = 32  # f_limit <= 30 segments after the first
_MAX_LENGTH = 12  # the longest step, f_length at |d| = 2 and k_scale = 2, in texels


def furrow(x, k_scale):
    """The §5.2 functions at |d| = x (clipped to [0, 2]):
    (angle, length, density, width, depth, limit)."""
    x = jnp.clip(x, 0.0, 2.0)
    return (1.0 - 0.4 * x, k_scale * (4.0 + x), k_scale * (1.0 + 6.0 * x), k_scale * x,
            0.25 * x * x, jnp.floor(30.0 - 10.0 * x).astype(jnp.int32))


def window_radius(k_scale: float) -> int:
    """Half-size of the window one step touches: half a segment plus half the marked band."""
    return int(math.ceil(k_scale * (6.0 / 2 + 13.0 / 2))) + 2


class FurrowRecord(NamedTuple):
    """Per furrow (first `records` of each pass) and half (+d, −d): how it ended
    (`END_*`), where (`end (…, 2)` pixels), its `segments` and `length` in texels; `seed`;
    per pass the number of furrows and the `owner` image (furrow id per texel)."""

    seed: jax.Array
    end: jax.Array
    reason: jax.Array
    segments: jax.Array
    length: jax.Array
    count: jax.Array  # furrows drawn in the pass
    owner: jax.Array  # (H, W) the furrow that drew each texel (-1: none)


@functools.partial(jax.jit, static_argnames=("radius", "records", "wrap"))
def height_field(mask, field1, field2, centroids, k_scale, key, radius: int, records: int = 0,
                 wrap: bool = False):
    """The wrinkle height field before noise (steps 1–8 of §3.3; `add_noise` is step 9).

    **Arguments:**

    - `mask (H, W)` bool: texels on the mesh.
    - `field1`, `field2 (H, W, 2)`: the fields in texture space (pixel frame, |d| in [0, 2]).
    - `centroids (F, 2)`: triangle centroids in pixels, the first seeds.
    - `k_scale`: the paper's scale.
    - `key`: a `jax.random` key.
    - `radius`: static window half-size, `window_radius(max k_scale)`.
    - `records`: how many furrows per pass to record in the returned `FurrowRecord`.
    - `wrap`: x is periodic (a cylinder's texture, one turn wide): furrows cross the seam,
      see and stop at the furrows beyond it, and are drawn on both sides of it.

    **Returns:** `(h (H, W) float32 in [0, 1] with 1 off the mesh, FurrowRecord)`.
    """
    k_scale = jnp.asarray(k_scale, jnp.float32)
    fields = jnp.stack([field1, field2]).astype(jnp.float32)
    keys = jnp.stack([jax.random.fold_in(key, 1), jax.random.fold_in(key, 2)])
    run = functools.partial(_pass, mask, centroids.astype(jnp.float32), k_scale,
                            radius=radius, records=max(records, 1), wrap=wrap)
    # Two passes one after the other, not vmapped: under vmap every window update becomes a
    # scatter that copies the whole image (an order of magnitude slower).
    (img1, rec1), (img2, rec2) = run(fields[0], keys[0]), run(fields[1], keys[1])
    rec = jax.tree.map(lambda a, b: jnp.stack([a, b]), rec1, rec2)
    return jnp.where(mask, jnp.minimum(img1, img2), 1.0), rec


def noise_field(shape, key, dtype=jnp.float32):
    """The r of step 9: uniform in [0, 1) per texel; fixed for a seed (compute it once)."""
    return jax.random.uniform(jax.random.fold_in(key, 3), shape, dtype)


def add_noise(h, mask, k_noise, r):
    """Step 9: h − r·k_noise on the mesh, `r` from `noise_field`. Linear in k_noise and h,
    so differentiable; the furrows and r are computed once per scene."""
    return jnp.where(mask, h - k_noise * r, h)


class _Pass(NamedTuple):
    """One pass's constants, shared by its steps: the texture's size `H, W`, the window
    half-size `R` and the padding `pad` around the buffers, the padded mesh mask `inside`,
    the field, the seeds (`centroids`, their texels `cpix`, `c_ok` where on the mesh), a
    window's offsets `win` and the sample points of a segment's crossing test."""

    H: int
    W: int
    R: int
    pad: int
    wrap: bool
    records: int
    inside: jax.Array
    field: jax.Array
    key: jax.Array
    k_scale: jax.Array
    centroids: jax.Array
    cpix: jax.Array
    c_ok: jax.Array
    win: jax.Array
    samples: jax.Array


def _pass(mask, centroids, k_scale, field, key, *, radius, records, wrap=False):
    """One field's image (§3.3 field steps 1–3, or 5–7): furrows from the seeds in order,
    each drawn by `_furrow`, until no unmarked seed is left."""
    H, W = mask.shape
    R = radius
    pad = R + _MAX_LENGTH + 2  # room for a window and a full step past the edge
    Hp, Wp = H + 2 * pad, W + 2 * pad
    inside = jnp.pad(mask, pad)
    cpix = jnp.floor(centroids).astype(jnp.int32)
    c_ok = (cpix[:, 0] >= 0) & (cpix[:, 0] < W) & (cpix[:, 1] >= 0) & (cpix[:, 1] < H)
    c_ok = c_ok & inside[cpix[:, 1] + pad, cpix[:, 0] + pad]
    win = jnp.arange(2 * R + 1)
    samples = jnp.arange(1, 2 * _MAX_LENGTH + 1, dtype=jnp.float32)  # <= half a texel apart
    samples = samples / samples.shape[0]
    t = _Pass(H, W, R, pad, wrap, records, inside, field, key, k_scale, centroids, cpix, c_ok,
              win, samples)

    img = jnp.ones((Hp, Wp), jnp.float32)
    state = jnp.zeros((Hp, Wp), jnp.int32)  # owner and B in one buffer: see _pack
    rec = (jnp.zeros((records, 2), jnp.float32), jnp.zeros((records, 2, 2), jnp.float32),
           jnp.full((records, 2), -1, jnp.int32), jnp.zeros((records, 2), jnp.int32),
           jnp.zeros((records, 2), jnp.float32))
    found, idx, point = _next_seed(t, state, jnp.int32(0))
    carry = (img, state, jnp.int32(0), found, idx, point, rec)
    carry = jax.lax.while_loop(lambda c: c[3], functools.partial(_furrow, t), carry)
    img, state, fid, rec = carry[0], carry[1], carry[2], carry[6]
    owner = _owner(state[pad:pad + H, pad:pad + W])
    return img[pad:pad + H, pad:pad + W], FurrowRecord(*rec, count=fid, owner=owner)


def _next_seed(t: _Pass, state, cursor):
    """Seed (§3.3 field steps 2–3): the first seed index >= cursor not marked in B,
    centroids first, then texels row by row. Returns `(found, index, point)`.

    Rows are scanned from the cursor's; the cursor only moves forward, so over a whole
    pass the scan costs O(H W) plus O(W) per furrow."""
    H, W, pad, inside = t.H, t.W, t.pad, t.inside
    n_cent = t.centroids.shape[0]
    c_free = t.c_ok & ~_marked(state[t.cpix[:, 1] + pad, t.cpix[:, 0] + pad]) & (
        jnp.arange(n_cent) >= cursor)
    c_any = jnp.any(c_free)
    c_idx = jnp.argmax(c_free)
    start = jnp.maximum(cursor - n_cent, 0)
    r0, col0 = start // W, start % W

    def free_row(r):
        row = (jax.lax.dynamic_slice(inside, (r + pad, pad), (1, W))[0]
               & ~_marked(jax.lax.dynamic_slice(state, (r + pad, pad), (1, W))[0]))
        return row & (jnp.arange(W) >= jnp.where(r == r0, col0, 0))

    def scan(c):
        r, _, _ = c
        row = free_row(r)
        found = jnp.any(row)
        return jnp.where(found, r, r + 1), found, jnp.argmax(row).astype(jnp.int32)

    r, t_any, col = jax.lax.while_loop(lambda c: ~c[1] & (c[0] < H), scan,
                                       (jnp.minimum(r0, H), jnp.bool_(False), jnp.int32(0)))
    t_idx = n_cent + r * W + col
    idx = jnp.where(c_any, c_idx, t_idx)
    point = jnp.where(c_any, t.centroids[jnp.minimum(c_idx, n_cent - 1)],
                      jnp.stack([col + 0.5, r + 0.5]).astype(jnp.float32))
    return c_any | t_any, idx, point


def _furrow(t: _Pass, carry):
    """One furrow from the current seed (§3.3 field step 2 or 3): grown along +d, then
    along −d (`_half`), recorded, and the next seed (found during its last step)."""
    (img, state, fid, _, idx, seed_point, rec) = carry
    fkey = jax.random.fold_in(t.key, fid)
    buffers = (img, state)
    outs = []
    search = (jnp.bool_(False), idx + 1, jnp.bool_(False), idx, seed_point)
    for h, sign in enumerate((1.0, -1.0)):
        search = (jnp.bool_(h == 1), *search[1:])
        buffers, out, search = _half(t, buffers, seed_point, fid, jnp.float32(sign),
                                     jax.random.fold_in(fkey, h), search)
        outs.append(out)
    img, state = buffers
    rec = _record(rec, fid, seed_point, outs, t.records)
    _, _, found, nidx, npoint = search
    return (img, state, fid + 1, found, nidx, npoint, rec)


def _half(t: _Pass, buffers, seed_point, fid, sign, hkey, search):
    """Grow one half of a furrow from its seed along sign·d (§3.3 furrow steps 1–6, from
    N_limit = ∞ until step 6 stops it, or `MAX_STEPS`). Returns the buffers, `(end,
    reason, segments, length)` and the seed search."""
    img, state = buffers
    carry = (seed_point, jnp.int32(2**30), jnp.int32(0), jnp.bool_(True), img, state,
             jnp.float32(0.0), jnp.int32(END_LIMIT), fid, sign, hkey, search)
    carry = jax.lax.while_loop(lambda c: c[3] & (c[2] < MAX_STEPS),
                               functools.partial(_step, t), carry)
    P, _, s, _, img, state, length, reason = carry[:8]
    return (img, state), (P, reason, s, length), carry[11]


def _step(t: _Pass, carry):
    """One segment P–Q of a furrow (§3.3 furrow steps 1–6)."""
    (P, n_limit, s, alive, img, state, length, reason, fid, sign, hkey, search) = carry
    direction, zero, f_len, density, width, depth, limit = _turn(t, P, sign, hkey, s)
    Q, any_hit, hit_furrow, k = _grow(t, P, direction, f_len, state, fid)
    draw = alive & ~zero
    img, state = _draw(t, img, state, P, Q, draw, width, depth, density, fid)
    stop, new_reason = _stop(zero, any_hit, hit_furrow, k, n_limit)
    search = _seed_after(t, state, search, alive & (stop | (s + 1 >= MAX_STEPS)))
    # Step 6's "P ← Q, N_limit ← min(N_limit, f_limit) − 1" (Q taken one turn back on a
    # cylinder), the length drawn, and how the half ended.
    v = Q - P
    Q = Q.at[0].set(jnp.mod(Q[0], t.W)) if t.wrap else Q
    return (jnp.where(draw, Q, P), jnp.minimum(n_limit, limit) - 1, s + 1, alive & ~stop,
            img, state, length + jnp.where(draw, jnp.linalg.norm(v), 0.0),
            jnp.where(alive & stop, new_reason, reason), fid, sign, hkey, search)


def _turn(t: _Pass, P, sign, hkey, s):
    """Grow, §3.3 furrow steps 1–2: d at P (sign·d for the −d half), the §5.2 functions of
    |d|, and the direction d turned by a uniform random angle in ±f_angle/2. Returns
    `(direction, zero, f_length, f_density, f_width, f_depth, f_limit)`, `zero` where
    |d| = 0 (no direction: the furrow stops there)."""
    ix = jnp.clip(jnp.floor(P[0]).astype(jnp.int32), 0, t.W - 1)
    iy = jnp.clip(jnp.floor(P[1]).astype(jnp.int32), 0, t.H - 1)
    d = sign * t.field[iy, ix]
    x = jnp.linalg.norm(d)
    zero = x < 1e-6
    angle, f_len, density, width, depth, limit = furrow(x, t.k_scale)
    theta = angle * (jax.random.uniform(jax.random.fold_in(hkey, s)) - 0.5)
    unit = d / jnp.where(zero, 1.0, x)
    c, sn = jnp.cos(theta), jnp.sin(theta)
    direction = jnp.stack([c * unit[0] - sn * unit[1], sn * unit[0] + c * unit[1]])
    return direction, zero, f_len, density, width, depth, limit


def _grow(t: _Pass, P, direction, f_len, state, fid):
    """Grow, §3.3 furrow step 3: move f_length from P; Q is the reached point, or the
    nearest crossing of the mesh border or of another furrow (a texel it owns) on the way.
    Returns `(Q, any_hit, hit_furrow, k)`: whether something was crossed, which samples
    crossed a furrow, and the first crossing's sample."""
    pad, W, wrap = t.pad, t.W, t.wrap
    Q0 = P + f_len * direction
    pts = P + t.samples[:, None] * (Q0 - P)
    pi = jnp.floor(pts).astype(jnp.int32) + pad
    px = (pi[:, 0] - pad) % W + pad if wrap else pi[:, 0]  # read one turn over
    on_mesh = t.inside[pi[:, 1], px]
    who = _owner(state[pi[:, 1], px])
    hit_furrow = (who >= 0) & (who != fid)
    hit = ~on_mesh | hit_furrow
    any_hit = jnp.any(hit)
    k = jnp.argmax(hit)
    Q = jnp.where(any_hit, pts[k], Q0)
    return Q, any_hit, hit_furrow, k


def _draw(t: _Pass, img, state, P, Q, draw, width, depth, density, fid):
    """Draw, §3.3 furrow steps 4–5: mark B within f_density/2 of P–Q and draw the segment
    f_width wide, f_depth deep (`_paint`); on a cylinder the part of the window past the
    seam is drawn again one turn over."""
    R, W = t.R, t.W
    img, state = _paint(t, img, state, P, Q, 0, draw, width, depth, density, fid)
    if t.wrap:  # the part of the window past the seam, drawn again one turn over
        c0 = jnp.floor((P[0] + Q[0]) / 2).astype(jnp.int32) - R
        shift = jnp.where(c0 < 0, W, jnp.where(c0 + 2 * R + 1 > W, -W, 0))
        img, state = _paint(t, img, state, P, Q, shift, draw & (shift != 0), width, depth,
                            density, fid)
    return img, state


def _paint(t: _Pass, img, state, P, Q, shift, draw, width, depth, density, fid):
    """Draw P–Q (moved `shift` texels along x) in the window around its midpoint: the
    image lowered by f_depth times the line's coverage, B marked, the owner set."""
    R, pad, win = t.R, t.pad, t.win
    P, Q = P.at[0].add(shift), Q.at[0].add(shift)
    c0 = jnp.floor((P + Q) / 2).astype(jnp.int32) - R  # window corner, unpadded
    ys = (c0[1] + win).astype(jnp.float32) + 0.5
    xs = (c0[0] + win).astype(jnp.float32) + 0.5
    v = Q - P
    tx, ty = xs[None, :] - P[0], ys[:, None] - P[1]
    tt = jnp.clip((tx * v[0] + ty * v[1]) / jnp.maximum(v @ v, 1e-12), 0.0, 1.0)
    dist = jnp.hypot(tx - tt * v[0], ty - tt * v[1])
    cover = jnp.clip(width / 2 + 0.5 - dist, 0.0, 1.0)
    corner = (c0[1] + pad, c0[0] + pad)
    size = (2 * R + 1, 2 * R + 1)
    img_w = jax.lax.dynamic_slice(img, corner, size)
    img_w = jnp.where(draw, jnp.minimum(img_w, 1.0 - depth * cover), img_w)
    # Everything that reads `state` here feeds its in-place update below. (A reader that
    # did not, a per-row count of free texels, made XLA copy the whole image each step.)
    st_w = jax.lax.dynamic_slice(state, corner, size)
    own_w, marked_w = _owner(st_w), _marked(st_w)
    own_w = jnp.where(draw & (cover > 0) & (own_w < 0), fid, own_w)
    mark = draw & (dist <= density / 2)
    img = jax.lax.dynamic_update_slice(img, img_w, corner)
    state = jax.lax.dynamic_update_slice(state, _pack(own_w, marked_w | mark), corner)
    return img, state


def _stop(zero, any_hit, hit_furrow, k, n_limit):
    """Stop, §3.3 furrow step 6: at N_limit = 0 or where step 3 met something (and where
    |d| = 0). Returns `(stop, reason)`, the reason an `END_*`."""
    stop = zero | any_hit | (n_limit == 0)
    reason = jnp.where(zero, END_ZERO, jnp.where(
        any_hit, jnp.where(hit_furrow[k], END_FURROW, END_BORDER), END_LIMIT))
    return stop, reason


def _seed_after(t: _Pass, state, search, ends):
    """Seed (§3.3 field steps 2–3), looked for here: after the last step of a furrow's
    second half (`ends` on the −d half), the next seed from the cursor on.

    Inside the step loop because a read of `state` in the outer loop makes XLA copy it at
    every step."""
    is_second, cursor, found, nidx, npoint = search
    last = ends & is_second
    found, nidx, npoint = jax.lax.cond(last, lambda: _next_seed(t, state, cursor),
                                       lambda: (found, nidx, npoint))
    return (is_second, cursor, found, nidx, npoint)


def _record(rec, fid, seed_point, outs, records):
    """The first `records` furrows' seed and, per half, end, reason, segments and length."""
    slot = jnp.minimum(fid, records - 1)
    keep = fid < records
    seed_r, end_r, reason_r, seg_r, len_r = rec
    seed_r = seed_r.at[slot].set(jnp.where(keep, seed_point, seed_r[slot]))
    end_r = end_r.at[slot].set(jnp.where(keep, jnp.stack([o[0] for o in outs]), end_r[slot]))
    reason_r = reason_r.at[slot].set(
        jnp.where(keep, jnp.stack([o[1] for o in outs]), reason_r[slot]))
    seg_r = seg_r.at[slot].set(jnp.where(keep, jnp.stack([o[2] for o in outs]), seg_r[slot]))
    len_r = len_r.at[slot].set(jnp.where(keep, jnp.stack([o[3] for o in outs]), len_r[slot]))
    return (seed_r, end_r, reason_r, seg_r, len_r)


# Owner and buffer B share one int32 array: bits 0–29 hold the owning furrow's id + 1
# (0: none), bit 30 the mark of B; one buffer instead of two halves what a step moves.
_MARK = 1 << 30


def _owner(v):
    return (v & (_MARK - 1)) - 1


def _marked(v):
    return (v & _MARK) != 0


def _pack(owner, marked):
    return (owner + 1) | jnp.where(marked, _MARK, 0)


def to_numpy_record(rec: FurrowRecord, records: int) -> dict:
    """The recorded furrows of both passes as NumPy arrays, trimmed to those drawn."""
    out = {}
    for p in range(2):
        n = min(int(rec.count[p]), records)
        out[p] = {f: np.asarray(getattr(rec, f)[p][:n]) for f in
                  ("seed", "end", "reason", "segments", "length")}
        out[p]["count"] = int(rec.count[p])
        out[p]["owner"] = np.asarray(rec.owner[p])
    return out
