"""fitting: parameters for jaxskin from measurements, with optimistix.

- `fitting.measurements`: spectroradiometer CSVs (thin layer, opaque layer, background).
- `fitting.km`: S(λ), K(λ) of a cosmetic (Huang et al. 2013 §4).
- `fitting.cards`: contrast cards (drawdowns): the film over a black and a white part.
- `fitting.coverage`: contrast ratio, 98 % hiding thickness, ΔE2000 over black vs white.
- `fitting.report`: the PNG report of a fit.
- `fitting.brdf`: Lafortune lobes from BRDF samples (`jaxskin fit-brdf`).
- `fitting.skin`: the biophysical skin from reflectance spectra (`jaxskin fit-skin`).
- `fitting.image`: scene values and texture-space maps from a target image
  (`jaxskin fit-image`, inverse rendering).
- `fitting.match`: colour matching, a mixture's concentrations (and film thickness) for a
  target spectrum or CIELAB colour (`jaxskin match`); `fitting.match_report` its JSON and PNG.

Fits run in float64 inside `jax.enable_x64(True)`; nothing here changes JAX's global settings.
"""

from .km import KMFit, closed_form, fit, identifiable
from .measurements import Measurement, read_measurement

__all__ = ["KMFit", "Measurement", "closed_form", "fit", "identifiable", "read_measurement"]
