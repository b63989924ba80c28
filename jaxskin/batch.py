"""The units of `jaxskin render`: a scene's image, its texture-space maps, or a batch of
sweep values, each a function of picklable arrays that runs here or on a cluster worker.

A sweep is cut into batches of `SWEEP_BATCH` values, every one padded to that size (a short
sweep's too: `sweep_batches`), each one call of one compiled, vmapped program
(`render_batch`): a value's image has the same bytes whatever the sweep around it and
wherever it runs. Within one process with several JAX devices a batch is sharded across
them (`shard_sweep`). `jaxskin.cluster` runs the units; this module only computes them.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

__all__ = ["SWEEP_BATCH", "render_batch", "render_unit", "scene_maps", "shard_sweep",
           "sweep_batches"]

SWEEP_BATCH = 8  # sweep values per task (and per compiled call when run here)


def sweep_batches(values, size: int = SWEEP_BATCH) -> list["np.ndarray"]:
    """`values` cut into batches of `size`, each padded with its last value to that length,
    however few the values: one shape, one compiled program, and the same bytes for a value
    whatever the sweep around it. (XLA compiles a vmapped program per batch size, and the
    programs round differently: on a 2-core CPU a batch of 1 and one of 8 gave makeup
    renders 1.6e-4 apart in display values, a few 8-bit samples off by one.) A sweep of
    fewer than `size` values pays for `size` renders."""
    import numpy as np

    values = np.asarray(values, np.float32)
    n = size
    out = []
    for i in range(0, len(values), n):
        b = values[i:i + n]
        out.append(np.concatenate([b, np.repeat(b[-1:], n - len(b))]))
    return out


def shard_sweep(values, devices=None):
    """Sweep values padded to a multiple of the device count and, with several devices,
    placed one slice per device (`NamedSharding` over a 1-D mesh): a jitted vmap over them
    then runs on every device at once. Returns `(values, sharding)`, the sharding `None`
    with one device."""
    import jax
    import numpy as np
    from jax.sharding import Mesh, NamedSharding, PartitionSpec

    devices = jax.devices() if devices is None else devices
    values = np.asarray(values, np.float32)
    extra = -len(values) % len(devices)
    values = np.concatenate([values, np.repeat(values[-1:], extra)])
    if len(devices) == 1:
        return values, None
    mesh = Mesh(np.asarray(devices), ("sweep",))
    return jax.device_put(values, NamedSharding(mesh, PartitionSpec("sweep"))), \
        NamedSharding(mesh, PartitionSpec())


@functools.lru_cache(maxsize=16)
def _sweep_program(config, key: str, output: str):
    """One compiled program per (configuration, swept key, output): the scene's parameters
    and prepared arrays are its arguments, so scenes sharing a configuration share it."""
    import jax

    from . import render

    def one(v, params, arrays):
        return render.render_prepared(config, {**params, key: v}, arrays, output)

    return jax.jit(jax.vmap(one, in_axes=(0, None, None)))


def render_unit(unit):
    """A unit of `jaxskin render`: `("images", config, params, key, values, output)` →
    `render_batch`, `("maps", config, params, glb)` → `scene_maps`."""
    kind, *rest = unit
    return render_batch(tuple(rest)) if kind == "images" else scene_maps(tuple(rest))


def scene_maps(unit) -> dict:
    """A scene's texture-space maps, `(config, params, glb)` → `height (H, W)`,
    `normals (H, W, 3)` and, with `glb`, the GLB's `albedo`, as NumPy arrays."""
    import numpy as np

    from . import render, texture

    config, params, glb = unit
    out = {k: np.asarray(v) for k, v in texture.texture_maps(config, params).items()}
    if glb:
        out["albedo"] = np.asarray(render.albedo(config, params))
    return out


def render_batch(unit) -> "np.ndarray":
    """A render unit, `(config, params, key, values, output)`: the images `(B, H, W, C)` of
    a batch of sweep values of `key` (all its values, padding included), or with `key`
    None one image `(H, W, C)` of the scene as it is. Runs here or on a worker."""
    import jax
    import numpy as np

    from . import render

    config, params, key, values, output = unit
    if key is None:
        return np.asarray(render.render(config, params, output))
    arrays = render.prepare(config).arrays
    values, replicated = shard_sweep(values)
    if replicated is not None:
        params, arrays = jax.device_put((params, arrays), replicated)
    return np.asarray(_sweep_program(config, key, output)(values, params, arrays))

