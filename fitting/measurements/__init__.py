"""Spectroradiometer measurement CSVs for Kubelka–Munk calibration (Huang et al. 2013 §4).

The format (also in the documentation, docs/reference/formats.md):

    # name: foundation_1          (optional; default: the file's stem, made safe)
    # thickness_mm: 0.15          (optional; the thickness of a bare `R` column)
    wavelength_nm,R_0.05mm,R_0.15mm,R_inf,R_g
    380,0.0712,0.1134,0.2051,0.0398
    ...

- `R_<X>mm`: reflectance of a thin layer X mm thick over the background (one or more).
- `R`: a thin layer whose thickness comes from `--thickness` or `# thickness_mm:`.
- `R_inf`: an opaque layer. `R_g`: the background alone (black or white card).
- Or a contrast card (drawdown): `R_over_black`, `R_over_white` (a film over the card's
  black and white parts; with `_<X>mm` for its thickness, or none: thickness from
  `--thickness`, `# thickness_mm:`, or not known), `R_g_black`, `R_g_white` (the parts
  alone); `R_inf` optional.
- Reflectance factors in [0, 1] (or 0–100 with `percent=True`).
- Raw radiance instead: the same columns with `E_` in place of `R_` (`E_0.15mm`, `E_inf`,
  `E_g`; `E_R_0.15mm` is accepted too) plus `E_white`, the barium sulfate standard; then
  R = E / E_white (eq. 8).

The header is the first row whose first cell names the wavelength (`wavelength_nm`, `nm`,
`Wavelength (nm)`, ...) and that has a column starting with `R` or `E`.

Anything else is an `InputError` naming the file, the line and the column.

The package's private files:

- `_read.py`: `read_measurement` and `Measurement`: the table, its notes, its name.
- `_columns.py`: each column's role and thickness; `# key:` values.
- `_readings.py`: wavelengths in nm; reflectances checked to lie in [0, 1].
"""

from jaxskin.formats import is_wavelength_column as is_wavelength_column

from ._columns import MAX_THICKNESS_MM as MAX_THICKNESS_MM
from ._columns import THIN_COLUMN as THIN_COLUMN
from ._columns import takes_thickness as takes_thickness
from ._read import USUAL_THICKNESS_MM as USUAL_THICKNESS_MM
from ._read import Measurement as Measurement
from ._read import read_measurement as read_measurement
from ._readings import MAX_RADIANCE as MAX_RADIANCE

__all__ = ["Measurement", "is_wavelength_column", "read_measurement", "takes_thickness"]
