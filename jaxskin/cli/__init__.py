"""The `jaxskin` command line.

    jaxskin --version
    jaxskin list                                          # built-in scenes, meshes, materials …
    jaxskin calibrate FILE.csv [FILE.csv ...] -o OUTDIR   # S(λ), K(λ) of cosmetics
    jaxskin mix A.json:0.2 B.json:0.8 -o OUTDIR           # a mixture's material (KM)
    jaxskin match TARGET.csv --from A.json,B.json -o DIR  # the mixture matching a colour
    jaxskin fit-brdf FILE.csv -o OUT.json [--lobes N]     # Lafortune lobes
    jaxskin render SCENE [SCENE ...] -o DIR --maps        # wrinkle height and normal maps
    jaxskin fit-skin SPECTRA.csv -o DIR                   # the biophysical skin, fitted
    jaxskin fit-image SCENE TARGET.png --fit KEY[,KEY] -o DIR   # inverse rendering
    jaxskin edit [SCENE] -o DIR                           # the editor in the browser

(`python -m jaxskin …` is the same.) Exit codes: 0 done; 2 bad input (a file, a column, a
value, an option, an output path, a run that cannot fit in memory), reported as one line
`jaxskin: error: …` before any work and with nothing written; 1 an unexpected failure (out of
memory, disk full, a bug): one line saying what failed and which files are complete, the
traceback only with `--debug`; 130 / 143 interrupted by SIGINT / SIGTERM: one line naming the
files finished. Output files are written under temporary names and renamed, so every file
present is complete; none is written outside the output folder or over an input.

The package is the application around the library: nothing in `jaxskin` or
`jaxskin.fitting` imports it. Its private modules:

- `_main`: the parser, assembled from the commands' modules, and `main`.
- `_process`: exit codes, the record of written files, SIGINT and SIGTERM.
- `_terminal`: one-line messages on stderr (`say`, `warn`, `note`), a pipe-safe stdout.
- `_options`: one-line parser errors, checked numbers, the options commands share.
- `_names`: output names from `-D` values and `--sweep`s.
- `_list`, `_calibrate`, `_render`, `_fit_image`, `_fit_brdf`, `_fit_skin`, `_edit`: one
  module per command, each with `add_parser(sub)` and `run(args, record)`; so are `_mix`
  and `_match`.
"""

from ._main import COMMANDS as COMMANDS
from ._main import main as main
from ._main import parser as parser
from ._process import EXIT_FAILURE as EXIT_FAILURE
from ._process import EXIT_INPUT as EXIT_INPUT
from ._process import EXIT_SIGINT as EXIT_SIGINT
from ._process import EXIT_SIGTERM as EXIT_SIGTERM
from ._process import Run as Run
from ._process import exit_now as exit_now
from ._process import holding_signals as holding_signals
from ._process import pending_signal as pending_signal
from ._process import raise_received as raise_received
from ._process import signals_received as signals_received

__all__ = ["COMMANDS", "EXIT_FAILURE", "EXIT_INPUT", "EXIT_SIGINT", "EXIT_SIGTERM", "Run",
           "exit_now", "holding_signals", "main", "parser", "pending_signal", "raise_received",
           "signals_received"]
