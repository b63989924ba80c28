"""File formats: the I/O layer between files and the pure array code.

Everything that reads or writes a data file lives here (or in `io.py`, which holds the error
type, atomic writes and the data folder): CSV tables as instruments export them, JSON
documents, the NIST skin spectra, Lafortune BRDF files and calibrated materials. The optics
modules (`km`, `skin`, `shading`) take and return arrays only.

CSV tables (`read_table`) are read as spectroradiometer software writes them:

- the delimiter is a comma, a tab or a semicolon (the one that splits the header into the
  most cells), fields may be quoted (`"R_inf"`); the text is UTF-8 (a byte-order mark is
  ignored), UTF-16 with a byte-order mark (Windows software's "Unicode") or Windows-1252;
- numbers use a decimal point: `0,45` (a decimal comma) is refused with a one-line error;
- a preamble before the header is skipped: free text, `key: value` or `key,value` lines;
  `# key: value` comments before the header are kept as metadata (`Table.meta`);
- the header is the first row whose first cell names the first column (e.g. `wavelength_nm`)
  and, where the reader asks, that has a cell naming one of the other columns;
- after it, blank lines and `#` lines are skipped; a trailing empty cell (a delimiter at the
  end of every row) is dropped.

Every problem is an `InputError` naming the file, the line and the column.

The package's private files, one kind of file each:

- `_text.py`: reading a text file (encodings, binary files named, size limit); a row's cells.
- `_tables.py`: CSV tables (`read_table`), their numbers, columns and shared checks.
- `_documents.py`: JSON documents, Lafortune BRDF files, calibrated material files.
- `_spectra.py`: the NIST skin spectra, haemoglobin extinction, spectra to fit.
"""

from ..io import data_dir as data_dir
from ._documents import EXTRAPOLATE as EXTRAPOLATE
from ._documents import MAX_SK_PER_MM as MAX_SK_PER_MM
from ._documents import MaterialFile as MaterialFile
from ._documents import read_json as read_json
from ._documents import read_lafortune as read_lafortune
from ._documents import read_material as read_material
from ._documents import write_json as write_json
from ._documents import write_lafortune as write_lafortune
from ._spectra import HAEMOGLOBIN_FILE as HAEMOGLOBIN_FILE
from ._spectra import NIST_FILE as NIST_FILE
from ._spectra import NIST_SUBJECTS as NIST_SUBJECTS
from ._spectra import haemoglobin_table as haemoglobin_table
from ._spectra import nist_reflectance as nist_reflectance
from ._spectra import nist_spectrum as nist_spectrum
from ._spectra import read_spectra as read_spectra
from ._tables import DECIMAL_COMMA as DECIMAL_COMMA
from ._tables import GAP_MIN_NM as GAP_MIN_NM
from ._tables import GAP_STEPS as GAP_STEPS
from ._tables import NEGATIVE_NOISE as NEGATIVE_NOISE
from ._tables import PERCENT_MEDIAN as PERCENT_MEDIAN
from ._tables import PERCENT_UNIT as PERCENT_UNIT
from ._tables import WAVELENGTH_HEADER as WAVELENGTH_HEADER
from ._tables import WAVELENGTH_RANGE_NM as WAVELENGTH_RANGE_NM
from ._tables import Table as Table
from ._tables import check_percent as check_percent
from ._tables import decimal_comma_note as decimal_comma_note
from ._tables import drop_repeats as drop_repeats
from ._tables import is_measurement_table as is_measurement_table
from ._tables import is_wavelength_column as is_wavelength_column
from ._tables import read_table as read_table
from ._tables import wavelength_gaps as wavelength_gaps
from ._text import BINARY_KINDS as BINARY_KINDS
from ._text import DELIMITERS as DELIMITERS
from ._text import MAX_BYTES as MAX_BYTES
from ._text import read_text as read_text
from ._text import text_rows as text_rows

__all__ = ["DECIMAL_COMMA", "MAX_SK_PER_MM", "NEGATIVE_NOISE", "NIST_FILE",
           "NIST_SUBJECTS", "PERCENT_MEDIAN", "PERCENT_UNIT", "WAVELENGTH_HEADER",
           "WAVELENGTH_RANGE_NM", "MaterialFile", "Table", "check_percent", "data_dir",
           "decimal_comma_note", "drop_repeats", "haemoglobin_table", "is_measurement_table",
           "is_wavelength_column", "nist_reflectance", "nist_spectrum", "read_json",
           "read_lafortune", "read_material", "read_spectra", "read_table", "read_text",
           "text_rows", "wavelength_gaps", "write_json", "write_lafortune"]
