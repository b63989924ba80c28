"""jaxskin: differentiable rendering of human skin and cosmetics in JAX.

Modules, one idea each:

- `jaxskin.km`: Kubelka–Munk layers (reflectance and transmittance, stacks, backgrounds).
- `jaxskin.spectral`: wavelength grids and spectrum → XYZ → linear sRGB in one matmul.
- `jaxskin.io`: input errors, atomic output files, the shipped data folder.

Everything numeric follows the dtype of its inputs; rendering defaults to float32
(`jaxskin.DEFAULT_DTYPE`), fitting (`fitting`) runs in float64.
"""

import jax.numpy as jnp

from . import km, spectral
from .io import InputError

__version__ = "0.1.0"
DEFAULT_DTYPE = jnp.float32

__all__ = ["DEFAULT_DTYPE", "InputError", "km", "spectral", "__version__"]
