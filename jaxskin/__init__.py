"""jaxskin: differentiable rendering of human skin and cosmetics in JAX.

Modules, one idea each:

- `mesh`, `fields`, `projection`, `raster`: a body part, its direction fields (Bando 2001
  §3.1), texture space (§3.2) and the one rasterizer (texture space and camera views).
- `wrinkles`, `bump`, `texture`: the furrow height field (§3.3) and bump normals (§4.1).
- `shading.blinn`, `shading.lafortune`: skin shading (§4.2).
- `scene`, `view`, `shadow`, `render`: TOML scenes → `render(config, params)`, the pure
  function; camera views, shadow maps from the light.
- `km`, `spectral`: Kubelka–Munk layers and spectra → colour (Huang et al. 2013).
- `precision`: every float32 product at full precision on every device (no TF32 on GPUs).
- `maps`, `export`, `io`, `outputs`, `resources`, `cli`: PNG (8/16-bit), OpenEXR and GLB
  output, input errors, output folders and names, memory estimates, the command line.

Everything numeric follows the dtype of its inputs; rendering defaults to float32
(`jaxskin.DEFAULT_DTYPE`), fitting (`fitting`) runs in float64.
"""

import importlib as _importlib

from .io import InputError

__version__ = "0.1.0"

__all__ = ["DEFAULT_DTYPE", "InputError", "km", "spectral", "__version__"]


def __getattr__(name: str):
    """`km`, `spectral` and `DEFAULT_DTYPE` (float32) on first use: importing the package
    does not import JAX (about a second), so that the `jaxskin` command can take SIGINT
    from its first moment (`_console`)."""
    if name in ("km", "spectral"):
        return _importlib.import_module(f".{name}", __name__)
    if name == "DEFAULT_DTYPE":
        import jax.numpy as jnp

        return jnp.float32
    raise AttributeError(f"module 'jaxskin' has no attribute {name!r}")


def __dir__():
    return sorted({*globals(), "DEFAULT_DTYPE", "km", "spectral"})
