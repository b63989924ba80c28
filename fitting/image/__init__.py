"""Inverse rendering: scene values and texture-space maps fitted to an image.

`jaxskin fit-image SCENE TARGET.png --fit KEY[,KEY...]` asks which values of the scene, seen
from its camera, make the target. The renderer is `render.render_prepared`, unchanged; the fit
moves some of its parameters:

- **Scalars** (`FitKey.kind == "scalar"` or `"vector"`): any differentiable scene value the
  scene's model uses (`Scene.params`: melanin, blood, light, exposure, k_bump, layer
  thickness, roughness, specular …). Each is bounded by its schema range through
  x = lo + (hi − lo) σ(z); `light.direction` is free (the renderer normalises it);
  `material.lafortune`, a Lafortune scene's lobes, with ρd and n through exp.
- **Maps** (`"map"`): per-texel factors in texture space, `(H, W)` like the texture, that
  multiply their scalar as a scene's greyscale image does (`skin_texels.texel_map`):
  `layer.NAME.map` (× the layer's thickness_mm) and `skin.melanin_map` (× skin.melanin),
  kept in [0, the schema's top] by a sigmoid, log-like near 0 (a step changes a texel by
  a fraction of its value: thicknesses span decades). A smoothness prior,
  a smoothed total variation between neighbouring texels on the mesh, fills the texels the
  camera does not see and damps the noise.

The loss is the weighted mean squared difference of display values (sRGB, clipped to [0, 1]
as a PNG holds them) over the pixels the mesh covers fully (and the mask, if any), plus the
prior. Optimisers (optimistix, stepped one iteration at a time for the progress bar):

- scalars only: Levenberg–Marquardt (`optimistix.LevenbergMarquardt`) on the residual image,
  its Jacobian by forward mode (one JVP per scalar);
- with maps: Levenberg–Marquardt with a per-texel block-diagonal Gauss–Newton matrix
  (`gauss_newton`, `texel_blocks`; why and what it measured: `MAP_SOLVER_NOTE`). Adam
  (`optimistix.OptaxMinimiser(optax.adam)`), L-BFGS and nonlinear CG stay as `solver=`
  choices for comparison.

How well an image can pin a map at all is `map_bounds`: the Cramér–Rao bound of each
texel's log value from the noise and the image's sensitivity to it.

The optics stays in `jaxskin.render`; reading and writing files is the command line's
(`jaxskin fit-image`, in `jaxskin.cli`; `write_report` here for the PNG report).

The package's files:

- `_keys.py`: the fitted keys (`FitKey`, `fit_keys`) and their value ↔ coordinate transforms.
- `_loss.py`: the loss's parts: pixel weights, the noise estimate, the total-variation prior.
- `_solve.py`: `fit`, the optimistix solvers stepped one at a time, and `ImageFit`.
- `_texel.py`: the maps' per-texel Gauss–Newton, its blocks and CG, and `map_bounds`.
- `_report.py`: the report PNG (`write_report`).
"""

from ._keys import DEGENERATE as DEGENERATE
from ._keys import MAP_SCALARS as MAP_SCALARS
from ._keys import FitKey as FitKey
from ._keys import fit_keys as fit_keys
from ._keys import map_keys as map_keys
from ._keys import schema as schema
from ._loss import ABOVE_NOISE as ABOVE_NOISE
from ._loss import PRIOR_EPS as PRIOR_EPS
from ._loss import noise_sigma as noise_sigma
from ._loss import total_variation as total_variation
from ._loss import weights as weights
from ._report import write_report as write_report
from ._solve import ADAM_RATE as ADAM_RATE
from ._solve import ImageFit as ImageFit
from ._solve import fit as fit
from ._solve import map_image as map_image
from ._texel import CG_RTOL as CG_RTOL
from ._texel import CG_STEPS as CG_STEPS
from ._texel import GN_RTOL as GN_RTOL
from ._texel import MAP_SOLVER_NOTE as MAP_SOLVER_NOTE
from ._texel import STEP_MAX as STEP_MAX
from ._texel import blur_gain as blur_gain
from ._texel import map_bounds as map_bounds
from ._texel import pcg as pcg
from ._texel import texel_blocks as texel_blocks
from ._texel import texel_jacobian as texel_jacobian
from ._texel import view_diagonal as view_diagonal
from ._texel import view_matrix as view_matrix

__all__ = ["DEGENERATE", "FitKey", "ImageFit", "MAP_SCALARS", "blur_gain", "fit", "fit_keys",
           "map_bounds", "noise_sigma", "pcg", "texel_blocks", "texel_jacobian", "view_diagonal",
           "view_matrix", "weights", "write_report"]
