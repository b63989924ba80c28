"""The `jaxskin` command line.

    jaxskin --version
    jaxskin list                                          # built-in scenes, meshes, materials …
    jaxskin calibrate FILE.csv [FILE.csv ...] -o OUTDIR   # S(λ), K(λ) of cosmetics
    jaxskin fit-brdf FILE.csv -o OUT.json [--lobes N]     # Lafortune lobes
    jaxskin render SCENE [SCENE ...] -o DIR --maps        # wrinkle height and normal maps
    jaxskin fit-skin SPECTRA.csv -o DIR                   # the biophysical skin, fitted
    jaxskin fit-image SCENE TARGET.png --fit KEY[,KEY] -o DIR   # inverse rendering

(`python -m jaxskin …` is the same.) Exit codes: 0 done; 2 bad input (a file, a column, a
value, an option, an output path, a run that cannot fit in memory), reported as one line
`jaxskin: error: …` before any work and with nothing written; 1 an unexpected failure (out of
memory, disk full, a bug): one line saying what failed and which files are complete, the
traceback only with `--debug`; 130 / 143 interrupted by SIGINT / SIGTERM: one line naming the
files finished. Output files are written under temporary names and renamed, so every file
present is complete; none is written outside the output folder or over an input.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import gc
import hashlib
import math
import os
import re
import signal
import sys
import threading
import time
import warnings
from pathlib import Path
from typing import NoReturn

from . import __version__, cluster
from .checks import (
    check_scene,
    empty_picture,
    idle_map_keys,
    picture_warnings,
    read_instead,
    reading,
    unused_overrides,
)
from .io import FitError, InputError
from .outputs import MAX_NAME, MAX_NAME_BYTES, Outputs, _control, check_name, slug

EXIT_FAILURE, EXIT_INPUT, EXIT_SIGINT, EXIT_SIGTERM = 1, 2, 130, 143


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: `jaxskin: error: …`, exit 2 (no usage block)."""

    def error(self, message):
        command = self.prog.removeprefix("jaxskin").strip()
        self.exit(EXIT_INPUT, f"jaxskin: error: {command + ': ' if command else ''}{message} "
                  f"(see {self.prog} --help)\n")


def _number(kind=float, lo=None, hi=None, above=None):
    """An argparse type: a finite `kind` in [lo, hi] (or > `above`); nan and inf refused."""
    def parse(text):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected {'an integer' if kind is int else 'a number'}, got {text!r}"
            ) from None
        bad = not math.isfinite(value) or (lo is not None and value < lo) or (
            hi is not None and value > hi) or (above is not None and value <= above)
        if bad:
            def fmt(x):
                return str(x) if isinstance(x, int) else f"{x:g}"

            rng = (f"> {fmt(above)}" if above is not None else f">= {fmt(lo)}" if lo is not None
                   else "")
            rng += f" and <= {fmt(hi)}" if hi is not None else ""
            noun = "an integer" if kind is int else "a finite number"
            raise argparse.ArgumentTypeError(f"expected {noun} {rng}, got {text!r}")
        return value

    parse.__name__ = kind.__name__
    return parse


class _Terminated(BaseException):
    """SIGTERM, raised in the main thread like KeyboardInterrupt is for SIGINT."""


_SIGNAL_ERRORS = {signal.SIGINT: KeyboardInterrupt, signal.SIGTERM: _Terminated}
_pending: list[int] = []  # a signal whose exception could not be raised where it arrived
_received: list[int] = []  # every signal the command's handler took
_collecting = [False]  # the garbage collector is running (and calling JAX's callback)
_holding = [False]  # every signal is held (`holding_signals`)


def _gc_start(phase, info):
    if phase == "start":
        _collecting[0] = True


def _gc_stop(phase, info):
    if phase == "stop":
        _collecting[0] = False


def _on_signal(signum, frame):
    """Raise KeyboardInterrupt / _Terminated where the signal arrived, unless that is inside
    the garbage collector's callbacks or a finaliser, where Python would print the exception
    and drop it, or inside an import, which some libraries wrap in `except BaseException`
    (trimesh's optional imports: the command ran on to exit 0; a trial): then it is kept
    and raised at the next `_raise_pending` (a stage change, or the command's end), or
    taken by `pending_signal` (the editor's event loop, `holding_signals`)."""
    _received.append(signum)
    if _collecting[0] or _holding[0] or _held_back(frame):
        _pending.append(signum)
        return
    raise _SIGNAL_ERRORS[signum]()


@contextlib.contextmanager
def holding_signals():
    """Hold every signal (`pending_signal` takes it) for the duration: for an asyncio event
    loop, which an exception raised anywhere in it can leave half made or half closed (a
    SIGTERM inside `new_event_loop` left a loop without its self-pipe, whose finaliser
    printed an AttributeError after the command's last line; CI; a third Ctrl-C raised
    inside aiohttp's shutdown, a review)."""
    _holding[0] = True
    try:
        yield
    finally:
        _holding[0] = False


def signals_received() -> int:
    """How many signals the command has received."""
    return len(_received)


def _signal_words(sig: int) -> tuple[str, int]:
    return ("interrupted", EXIT_SIGINT) if sig == signal.SIGINT else ("terminated", EXIT_SIGTERM)


def exit_now(run: _Run) -> NoReturn:
    """For a second signal while a command waits on work a signal cannot stop (the editor's
    render in its worker thread): the command's last line, then the process ends at once,
    not waiting for that work (it writes nothing; a Save caught halfway may leave its
    temporary file)."""
    sig = _received[-1]
    word, code = _signal_words(sig)
    _say(f"jaxskin: {word} ({signal.Signals(sig).name}) while {run.stage}; {run.finished()}")
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def pending_signal() -> bool:
    """Whether a signal is held back (`_on_signal`); it is taken off the list (still in
    `raise_received`'s)."""
    if _pending:
        _pending.clear()
        return True
    return False


def raise_received() -> None:
    """Raise the last signal the command received, if any: for a command whose library
    swallows the exception a signal raised (aiohttp's `run_app` returns on
    KeyboardInterrupt), so that it still ends with 130 / 143 and its line."""
    if _received:
        raise _SIGNAL_ERRORS[_received[-1]]()


def _held_back(frame) -> bool:
    """Whether `frame` is in a finaliser or JAX's collector callback, or inside an import."""
    if frame is not None and frame.f_code.co_name in ("__del__", "_xla_gc_callback"):
        return True
    while frame is not None:
        if frame.f_code.co_filename.startswith("<frozen importlib"):
            return True
        frame = frame.f_back
    return False


def _raise_pending() -> None:
    """Raise a signal that arrived where it could not be raised (see `_on_signal`)."""
    if _pending:
        raise _SIGNAL_ERRORS[_pending.pop(0)]()


@contextlib.contextmanager
def _signals():
    """SIGINT → KeyboardInterrupt, SIGTERM → _Terminated, for the duration of a command
    (atomic_write removes its temporary file on either), and warnings as one line each; the
    old handlers come back after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old_format = warnings.formatwarning
    warnings.formatwarning = _warning_line
    old = {sig: signal.getsignal(sig) for sig in _SIGNAL_ERRORS}
    _pending.clear()
    _received.clear()
    # First and last of the collector's callbacks, so that JAX's (which runs Python code in
    # both phases) sits between them.
    gc.callbacks.insert(0, _gc_start)
    gc.callbacks.append(_gc_stop)
    for sig in _SIGNAL_ERRORS:
        signal.signal(sig, _on_signal)
    try:
        yield
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
        for callback in (_gc_start, _gc_stop):
            if callback in gc.callbacks:
                gc.callbacks.remove(callback)
        _collecting[0] = False
        warnings.formatwarning = old_format


def _warning_line(message, category, filename, lineno, line=None) -> str:
    """A warning as one line, `jaxskin: warning: …` (not Python's two with the source)."""
    return f"jaxskin: warning: {' '.join(str(message).split())}\n"


# The last line after a failure or a signal names at most this many of the files written
# (the last ones); a 400-image sweep stopped halfway once printed a line of 19 KB.
SHOWN_NAMES = 8


class _Run:
    """What a command has written so far: for the last line after a failure or a signal."""

    def __init__(self, stage: str = "checking the inputs"):
        self.outputs: list[Outputs] = []
        self._stage = stage

    @property
    def stage(self) -> str:
        """What the command is doing, for the last line; setting it is also where a signal
        held back by `_on_signal` is raised."""
        return self._stage

    @stage.setter
    def stage(self, text: str) -> None:
        _raise_pending()
        self._stage = text

    def finished(self) -> str:
        # each file once, where it was last written (the editor saves one name again)
        written = list(reversed(dict.fromkeys(
            reversed([p for o in self.outputs for p in o.written]))))
        if not written:
            return "no file was written"
        folders = sorted({str(p.parent) for p in written})
        shown = SHOWN_NAMES if len(written) > SHOWN_NAMES + 1 else len(written)
        names = ", ".join(p.name for p in written[-shown:])  # the last ones: where it stopped
        if shown < len(written):
            names = f"… ({len(written) - shown} more), {names}"
        return (f"{len(written)} file(s) complete in {', '.join(folders)}: {names}; no partial "
                "file is left")


def _enable_compilation_cache() -> None:
    """Persist compiled programs across runs (JAXSKIN_NO_COMPILE_CACHE=1 switches it off)."""
    if os.environ.get("JAXSKIN_NO_COMPILE_CACHE", "") not in ("", "0"):
        return
    import jax

    root = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    path = os.environ.get("JAXSKIN_CACHE_DIR") or os.path.join(root, "jaxskin", "jax")
    try:
        os.makedirs(path, exist_ok=True)
    except OSError:
        return  # an unwritable home is no reason to fail; we just compile again
    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)


def _parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog="jaxskin",
        description="Differentiable rendering of human skin and cosmetics in JAX, with fitting. "
        "Also runs as `python -m jaxskin`.",
        epilog="Exit codes: 0 done, 2 bad input (one line, nothing written), 1 unexpected "
        "failure (one line; the traceback with --debug), 130 SIGINT, 143 SIGTERM. "
        "Environment: JAXSKIN_NO_COMPILE_CACHE=1 turns off the compilation cache kept in "
        "$XDG_CACHE_HOME/jaxskin (or JAXSKIN_CACHE_DIR).",
    )
    p.add_argument("--version", action="version", version=f"jaxskin {__version__}")
    p.add_argument("--debug", action="store_true",
                   help="on an unexpected failure, print the traceback too")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    sub.add_parser("list", help="list the built-in scenes, meshes, materials, BRDF presets, "
                   "illuminants and spectral steps",
                   description="One line for each built-in thing a scene can name.")

    c = sub.add_parser(
        "calibrate",
        help="fit Kubelka–Munk S(λ), K(λ) of cosmetics to spectroradiometer CSVs",
        description="Fit scattering S(λ) and absorption K(λ) (per mm) of each cosmetic from a "
        "CSV of thin-layer (R_<X>mm), opaque (R_inf) and background (R_g) reflectances, or raw "
        "radiances (E_… and E_white). Writes OUTDIR/<name>.json (the material file the "
        "renderer reads) and OUTDIR/<name>.png (a report). Every file is checked before any "
        "fit runs: one bad file writes nothing. The CSV format: docs/reference/formats.md.",
    )
    c.add_argument("files", nargs="+", metavar="FILE.csv", help="measurement CSVs")
    c.add_argument("-o", "--output", required=True, metavar="OUTDIR",
                   help="folder for <name>.json and <name>.png (created if missing)")
    c.add_argument("--thickness", type=_number(above=0.0, hi=100.0), metavar="MM",
                   help="thickness in mm of a bare 'R' column (overrides '# thickness_mm:'); "
                   "warned of when no file has one")
    c.add_argument("--percent", action="store_true",
                   help="reflectance columns are in percent (0–100) instead of 0–1 (without "
                   "it, a file whose reflectances have a median above 1.5 is read as percent, "
                   "with a note)")
    c.add_argument("--white-reflectance", type=_number(above=0.0, hi=1.0), metavar="R",
                   help="the white standard's certified reflectance (0-1; overrides '# "
                   "white_reflectance:'): radiance columns give R = E / E_white × R (default "
                   "1, Huang et al.'s barium sulfate)")
    c.add_argument("--ignore", action="append", default=[], metavar="COLUMN",
                   help="skip this column in every file (repeatable; a pattern such as "
                   "'SD_*' in quotes skips all that match): standard deviations, counts, "
                   "notes. A file can also say '# ignore: NAME, NAME' itself")
    # The bounds are fitting.km's MAX_SMOOTH and MAX_NOISE (not imported: that imports JAX,
    # and --help stays quick; tests/test_calibrate.py checks that they agree).
    c.add_argument("--smooth", type=_number(lo=0.0, hi=1e6), default=0.0, metavar="W",
                   help="smoothness prior: neighbouring bands' log S and log K differ by about "
                   "1/W (a Gaussian prior weighed against readings of σ = --noise); 0 (default) "
                   "fits each band on its own; 20 allows about 5%% per band")
    c.add_argument("--noise", type=_number(above=0.0, hi=0.5), default=None, metavar="σ",
                   help="standard deviation of one reflectance reading, > 0 and <= 0.5 "
                   "(default 0.002); a band is identifiable when some thin layer and the "
                   "background each differ from R_inf by more than 3σ; a fit whose RMS error "
                   "is above 3σ is warned of")
    c.add_argument("--extrapolate", choices=("hold", "linear"), default=None,
                   help="how the renderer may extend S, K beyond the measured wavelengths to "
                   "its 380-780 nm grid: hold the end values, or continue log S, log K "
                   "linearly; without it a material that does not cover the grid is refused "
                   "at render time (calibrate warns). The report draws the extension; "
                   "calibrate warns where it makes up over half the grid, or where 'linear' "
                   "carries S or K more than tenfold")
    c.add_argument("--no-report", action="store_true", help="write the JSON only, no PNG")
    cluster.add_option(c, "file")

    r = sub.add_parser(
        "render",
        help="render scenes to PNG (and their texture-space maps)",
        description="Render one or more scenes: a built-in name (hand, foot, arm: Bando 2001 "
        "figs. 6.1-6.3; face, makeup: Huang et al. 2013; see jaxskin list) or a TOML scene "
        "file (format: docs/reference/scene.md on the documentation site; every key with its "
        "default and range: python -m pydoc jaxskin.scene). Writes "
        "DIR/<scene>.png "
        "(or .exr, --format); "
        "with --maps also DIR/<scene>_height.png (16-bit grey), DIR/<scene>_normal.png (the "
        "bump-mapped normal map) and DIR/<scene>_field.png (the mesh with d1 in red and d2 in "
        "green, as in the paper's fig. 3.4). With -D overrides the name gets "
        "_<key>-<value> for each (DIR/hand_material.melanin-0.5.png; past 120 characters "
        "_D-<12 hex digits>, a digest of the overrides; -D name=NAME gives NAME alone), a "
        "sweep "
        "_sweep-<index>_<key>-<value> with a zero-padded index (DIR/hand_sweep-02_"
        "material.melanin-0.25.png; --maps and --glb are written once, for the scene's own "
        "value of the swept key). A file of the same name in DIR is replaced (an input of the "
        "run never is). A scene name must be a plain file name (no '/' or '\\', leading dot "
        "or control character) or it is refused. Everything is checked before "
        "anything is written: every scene, override, sweep, mesh, material, BRDF file, layer "
        "image and polygon, the output folder, that no output is an input, and that the "
        "render fits in memory. All scenes render in one process (or on a Dask cluster, "
        "--cluster); each static configuration compiles once (per worker).",
    )
    r.add_argument("scenes", nargs="+", metavar="SCENE", help="built-in name or TOML file")
    r.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder")
    r.add_argument("--maps", action="store_true",
                   help="also write the texture-space maps (height, normals, fields)")
    r.add_argument("--format", choices=("png", "png16", "exr"), default="png",
                   help="image format: png (8-bit, default), png16 (16-bit PNG), exr (linear "
                   "OpenEXR, float32 RGBA with premultiplied alpha; needs pip install "
                   "'jaxskin[exr]')")
    r.add_argument("--alpha", action="store_true",
                   help="PNG with an alpha channel: alpha = the mesh's coverage of each pixel "
                   "(antialiased with camera.supersample), the colour straight (not "
                   "premultiplied); EXR always has alpha")
    r.add_argument("--glb", action="store_true",
                   help="also write DIR/<scene>.glb: the mesh with its skin colour and the "
                   "wrinkle normal map as textures (opens in Blender or any glTF viewer)")
    r.add_argument("--sweep", action="append", default=[], metavar="KEY=START:STOP:COUNT",
                   help="render COUNT images with a parameter from START to STOP, vmapped in "
                   "batches of 8 values by one compiled program (fewer are padded to 8: a "
                   "value's image has the same bytes in any sweep), e.g. --sweep "
                   "material.melanin=0:1:5; writes "
                   "DIR/<scene>_sweep-<i>_<key>-<value>.png. One --sweep a command (a grid "
                   "of two keys: one command per value of the second, with -D); of several "
                   "scenes, one without the key is rendered once, with a warning")
    r.add_argument("-D", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene value, e.g. -D wrinkles.k_scale=1.3, -D "
                   "camera.rotate=0,60,0 (a list: numbers with commas, or TOML's [0, 60, 0]) "
                   "or -D layer.blush.material=foundation_dark (a shipped material or a "
                   "calibrate JSON; paths from the working directory); repeatable; applies to "
                   "every scene")
    cluster.add_option(r, f"batch of {cluster.SWEEP_BATCH} sweep values, or scene")

    f = sub.add_parser(
        "fit-image",
        help="fit scene values and texture-space maps to a target image (inverse rendering)",
        description="Fit the named values of a scene to TARGET, an image seen from the "
        "scene's camera (same size): scalars (any differentiable key: material.melanin, "
        "light.intensity, layer.NAME.thickness_mm, ...) by Levenberg-Marquardt, and "
        "texture-space maps (layer.NAME.map, skin.melanin_map; biophysical skin: "
        "skin.melanin_fraction_map, skin.haemoglobin_map) with a smoothness prior by a "
        "per-texel Gauss-Newton (Levenberg-Marquardt). The loss is the mean squared "
        "difference of display values over the pixels the "
        "mesh covers fully (and the mask's, if any). Writes DIR/<name>.toml (the scene with "
        "the fitted values; jaxskin render turns it into the fitted image), DIR/<name>_<map "
        "key>.png (each fitted map, 16-bit grey, loaded by that scene) and DIR/<name>_fit.png "
        "(target, fit, residual, loss, maps). Warns when two fitted keys trade off against "
        "each other (exposure and intensity, albedo and intensity).",
    )
    f.add_argument("scene", metavar="SCENE", help="built-in name or TOML file: the start")
    f.add_argument("target", metavar="TARGET.png", help="the image to fit")
    f.add_argument("--fit", required=True, metavar="KEY[,KEY...]", help="the keys to fit")
    f.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder")
    f.add_argument("--mask", metavar="M.png", help="weights in [0, 1] per pixel (grey; 0: "
                   "ignore), the target's size")
    f.add_argument("--steps", type=_number(int, 1, 100000), default=100, metavar="N",
                   help="at most N optimiser steps, 1-100000 (100)")
    f.add_argument("--smooth", type=_number(lo=0.0, hi=1e6), default=1e-6, metavar="W",
                   help="weight of the maps' total-variation prior (1e-6; 1e-5 pulled the "
                   "makeup maps flat at noise 0.01)")
    cluster.add_option(f, "fit (the whole fit: one task, no per-step progress)")
    f.add_argument("--solver", choices=("auto", "gn", "adam"), default="auto",
                   help="maps: gn, the per-texel Gauss-Newton (auto's choice: fewer steps, "
                   "fits to the noise), or adam (cheaper steps); scalars alone: "
                   "Levenberg-Marquardt either way")
    f.add_argument("-D", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene value (the fit's start), as for render")

    b = sub.add_parser(
        "fit-brdf",
        help="fit Lafortune lobes to BRDF samples",
        description="Fit the diffuse term ρd and N Lafortune lobes (Cxy, Cz, n) per RGB channel "
        "to BRDF samples: a CSV with theta_in_deg, phi_in_deg, theta_out_deg, phi_out_deg "
        "(or unit vectors wi_x, wi_y, wi_z, wo_x, wo_y, wo_z; local frame, z = normal), R, G, B "
        "in 1/sr, and an optional weight column. Writes OUT.json, the material file the "
        "renderer reads ('diffuse' is ρd; the model divides by π), with the relative RMS error "
        "per channel, and OUT.png, in-plane slices of samples and fit.",
    )
    b.add_argument("file", metavar="FILE.csv", help="BRDF samples")
    b.add_argument("-o", "--output", required=True, metavar="OUT.json",
                   help="the material file to write (the report goes beside it as .png)")
    b.add_argument("--lobes", type=_number(int, 1, 16), default=3, metavar="N",
                   help="lobes per channel, 1-16 (3)")
    b.add_argument("--starts", type=_number(int, 1, 1024), default=8, metavar="S",
                   help="starts per channel, 1-1024, half from typical lobe shapes, half "
                   "random (8); the best finite fit wins")
    b.add_argument("--seed", type=_number(int, 0, 2147483647), default=0,
                   help="seed of the random starts, 0-2147483647 (0)")
    b.add_argument("--no-report", action="store_true", help="write the JSON only, no PNG")
    cluster.add_option(b, "RGB channel")

    k = sub.add_parser(
        "fit-skin",
        help="fit the biophysical skin model to measured reflectance spectra",
        description="Fit melanin (fraction, eumelanin share), haemoglobin (fraction, "
        "oxygenation), epidermis thickness and scattering of the biophysical skin model "
        "(material.model = \"biophysical\") to each spectrum of a CSV: a wide table "
        "(wavelength_nm, then one column per spectrum, 0-1) or the NIST skin file's layout "
        "(each subject's Average). Fits 380-780 nm (needs at least 400-700). Writes "
        "DIR/<SPECTRA>_fit.csv (name, parameters, RMS reflectance error, dE2000 under D65 "
        "between measured and fitted spectra) and DIR/<SPECTRA>_fit.png (a sample of fits, "
        "histograms), named by the CSV's stem.",
    )
    k.add_argument("file", metavar="SPECTRA.csv", help="reflectance spectra")
    k.add_argument("-o", "--output", required=True, metavar="DIR",
                   help="folder for <SPECTRA>_fit.csv and .png (created if missing)")
    k.add_argument("--starts", type=_number(int, 1, 256), default=4, metavar="S",
                   help="starts per spectrum, 1-256: the default skin, then random (4)")
    k.add_argument("--seed", type=_number(int, 0, 2147483647), default=0,
                   help="seed of the random starts, 0-2147483647 (0)")
    k.add_argument("--fix", action="append", default=[], metavar="NAME=VALUE",
                   help="hold a parameter at a value, e.g. --fix epidermis_mm=0.06 "
                   "(repeatable)")
    k.add_argument("--percent", action="store_true",
                   help="reflectance is in percent (0-100) instead of 0-1 (without it, spectra "
                   "whose median is above 1.5 are read as percent, with a note)")
    k.add_argument("--no-report", action="store_true", help="write the CSV only, no PNG")
    cluster.add_option(k, "chunk of 10 spectra")

    e = sub.add_parser(
        "edit",
        help="edit a scene interactively in the browser (sliders, field edits, painting)",
        description="Start a local web server with an editor for SCENE (default: hand): the "
        "rendered view, every scene value as a slider, direction-field edits picked on the "
        "mesh, cosmetic layers painted on the face; Save writes DIR/<name>.toml (and painted "
        "maps as 16-bit PNGs) that jaxskin render reproduces. Needs pip install "
        "'jaxskin[edit]'. Files the page opens must lie in the scene's folder or DIR.",
    )
    e.add_argument("scene", nargs="?", metavar="SCENE", help="built-in name or TOML file")
    e.add_argument("-o", "--output", default=".", metavar="DIR",
                   help="folder Save writes to (default: the current folder)")
    e.add_argument("--port", type=_number(int, 0, 65535), default=0,
                   help="port to serve on (default 0: a free one)")
    e.add_argument("--host", default="127.0.0.1",
                   help="address to serve on (default 127.0.0.1: this machine only; others "
                   "are warned about)")
    e.add_argument("--no-browser", action="store_true", help="do not open a browser")
    e.add_argument("-D", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="start with a scene value changed, as jaxskin render -D (repeatable)")
    return p


def _list(args, run: _Run) -> int:
    """One line per built-in scene, mesh, material, BRDF preset, illuminant, spectral step."""
    from . import cosmetics, spectral
    from .mesh import BUILTIN as MESHES
    from .scene import builtin_scenes

    _raise_pending()  # after the imports: a signal held inside one is raised here, before
    # any line (it was raised at the end, the whole list printed first; a review)

    def first_comment(path: Path, width: int = 100) -> str:
        """The first sentence of the scene file's opening comment (at most `width` long)."""
        lines = path.read_text(encoding="utf-8").splitlines()
        text = " ".join(line.lstrip("# ").strip() for line in
                        lines[:next((i for i, t in enumerate(lines) if not t.startswith("#")),
                                    len(lines))])
        text = re.split(r"(?<=\.) (?=[A-Z])", text)[0]
        return text if len(text) <= width else text[:width].rsplit(" ", 1)[0] + " …"

    rows = [("scene", name, first_comment(path)) for name, path in builtin_scenes().items()]
    rows += [("mesh", name, f"data/meshes/{file}") for name, file in MESHES.items()]
    for name in cosmetics.shipped_materials():
        rows.append(("material", name, "a calibrated cosmetic (S, K per mm; data/materials)"))
    rows.append(("brdf", "skin", "Lafortune preset: pbrt-v1's 3-lobe fit to measured skin "
                 "(material.brdf; or a JSON from jaxskin fit-brdf)"))
    for name in spectral.ILLUMINANTS:
        rows.append(("illuminant", name, f"CIE illuminant {name} (spectral.illuminant)"))
    for step in spectral.STEPS:
        n = len(spectral.Grid(step).wavelengths)
        rows.append(("step", f"{step}", f"{step} nm: {n} bands, 380-780 nm "
                     f"(spectral.step = {step})"))
    for kind, name, text in rows:
        print(f"{kind:<10} {name:<20} {text}")
    return 0


def _calibrate(args, run: _Run) -> int:
    from jaxskin.fitting import km as fit_km
    from jaxskin.fitting.measurements import read_measurement

    noise = fit_km.DEFAULT_NOISE if args.noise is None else args.noise
    outputs = Outputs(args.output, args.files)
    # Check everything first: a bad file anywhere means nothing is written.
    measurements, paths = [], []
    for f in args.files:
        m = read_measurement(f, thickness_mm=args.thickness, percent=args.percent,
                             ignore=args.ignore, white_reflectance=args.white_reflectance)
        check_name(m.name, f, key="name")
        json_path = outputs.plan(f"{m.name}.json", f)
        png_path = None if args.no_report else outputs.plan(f"{m.name}.png", f)
        if not fit_km.identifiable(m, noise).any():
            fit_km.fit(m, noise=noise)  # raises the InputError that explains why
        measurements.append(m)
        paths.append((json_path, png_path))
    run.outputs.append(outputs)

    from jaxskin.fitting.report import far_extrapolation, write_report
    from jaxskin.formats import wavelength_gaps, write_json
    from jaxskin.spectral import Grid

    grid = Grid().wavelengths
    for m in measurements:
        for note in m.notes:
            print(f"jaxskin: note: {note}", file=sys.stderr)
        wl = m.wavelength_nm
        if args.extrapolate is None and (wl[0] > grid[0] or wl[-1] < grid[-1]):
            print(f"jaxskin: warning: {m.path}: covers {wl[0]:g}-{wl[-1]:g} nm, not the "
                  f"renderer's {grid[0]:g}-{grid[-1]:g} nm: the material will be refused at "
                  "render time; pass --extrapolate hold|linear to allow it", file=sys.stderr)
        share = (min(wl[-1], grid[-1]) - max(wl[0], grid[0])) / (grid[-1] - grid[0])
        if args.extrapolate is not None and share < 0.5:
            part = f"{share:.0%} of" if share > 0 else "none of"
            print(f"jaxskin: warning: {m.path}: covers {wl[0]:g}-{wl[-1]:g} nm, {part} the "
                  f"renderer's {grid[0]:g}-{grid[-1]:g} nm: --extrapolate {args.extrapolate} "
                  "makes up the rest", file=sys.stderr)
        for line in wavelength_gaps(wl):
            print(f"jaxskin: warning: {m.path}: {line}", file=sys.stderr)
        for line in fit_km.suspect_labels(m, noise):
            print(f"jaxskin: warning: {line}", file=sys.stderr)
    if args.thickness is not None and not any({"R", "E"} & set(m.columns)
                                              for m in measurements):
        print(f"jaxskin: warning: --thickness {args.thickness:g} was ignored: no file has a bare "
              "R (or E) column; each gives its thicknesses in its column names (R_<X>mm)",
              file=sys.stderr)

    rows, mismatched = [], []
    fit = functools.partial(fit_km.fit, smooth=args.smooth, noise=noise)
    with cluster.pool(args.cluster) as pool:
        run.stage = f"fitting {measurements[0].name}"
        results = pool.map(fit, measurements, desc="calibrate", unit="file")
        for k, (m, (json_path, png_path), (result, dt)) in enumerate(
                zip(measurements, paths, results, strict=True)):
            t0 = time.perf_counter()
            run.stage = f"writing {m.name}"
            write_json(result.to_json(m, extrapolate=args.extrapolate), json_path)
            outputs.done(json_path)
            for line in far_extrapolation(m, result, args.extrapolate, grid):
                print(f"jaxskin: warning: {m.path}: {line}", file=sys.stderr)
            if png_path is not None:
                write_report(m, result, png_path, args.extrapolate)
                outputs.done(png_path)
            elif json_path.with_suffix(".png").exists():
                mismatched.append(f"{json_path.with_suffix('.png')} is an earlier run's report "
                                  f"(--no-report): it does not show this fit of {m.name}; "
                                  "left as it is")
            rows.append((m.name, result, dt + time.perf_counter() - t0))
            if result.rmse > fit_km.NOISE_SIGMAS * noise:
                mismatched.append(
                    f"{m.path}: the fit's RMS error {result.rmse:.2g} is "
                    f"{result.rmse / noise:.1f}x --noise {noise:g}: S, K do not reproduce the "
                    "readings (columns or thicknesses mislabelled, or readings noisier than "
                    "--noise: see the report)")
            if k + 1 < len(measurements):
                run.stage = f"fitting {measurements[k + 1].name}"
    for line in mismatched:
        print(f"jaxskin: warning: {line}", file=sys.stderr)
    wide = max([24, *(len(name) for name, _, _ in rows)])  # long names kept the columns
    print(f"{'material':<{wide}} {'bands':>5} {'identifiable':>12} {'rmse':>9} {'steps':>5} "
          f"{'time s':>7}")
    for name, r, dt in rows:
        flag = "" if r.converged else "  (not converged: see report)"
        print(f"{name:<{wide}} {len(r.wavelength_nm):>5} {int(r.identifiable.sum()):>12} "
              f"{r.rmse:>9.2e} {r.steps:>5} {dt:>7.2f}{flag}")
    _print_written(outputs)
    return 0


def _print_written(outputs: Outputs) -> None:
    print(f"wrote {len(outputs.written)} file(s) to {outputs.folder}/:")
    for path in outputs.written:
        print(f"  {path}")


def _warn_repeated(overrides) -> None:
    """A warning per key given with -D more than once with different values: the last one
    is used, and the output names list each."""
    seen: dict[str, list[str]] = {}
    for item in overrides:
        key, value = (s.strip() for s in item.partition("=")[::2])
        seen.setdefault(key, []).append(value)
    for key, values in seen.items():
        if len({_name_value(key, v) for v in values}) > 1:
            _say(f"jaxskin: warning: -D {key} is given {len(values)} times ("
                 f"{', '.join(values)}): the last, {values[-1]}, is used")


def _parse_sweep(text: str, sc):
    """`key=start:stop:count` over a scalar parameter of scene `sc` → (key, values); the
    ends are checked like `-D` values (finite, in the key's range)."""
    import numpy as np

    from .scene import check_value

    key, sep, spec = text.partition("=")
    key = key.strip()
    parts = spec.split(":")
    try:
        start, stop, count = float(parts[0]), float(parts[1]), int(parts[2])
        ok = bool(sep) and len(parts) == 3
    except (ValueError, IndexError):
        ok = False
    if not ok:
        raise InputError(f"--sweep expects key=start:stop:count (count an integer), got "
                         f"{text!r}")
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise InputError(f"start and stop must be finite numbers, got {start:g} and {stop:g}",
                         f"--sweep {text}", key=key)
    if not 1 <= count <= 1000:
        raise InputError(f"count must be in [1, 1000], got {count}", f"--sweep {text}",
                         key=key)
    params = sc.params
    if not _sweeps(sc, text):
        import difflib

        from .scene import SCHEMA

        names = [k for k, v in params.items() if getattr(v, "ndim", 1) == 0]
        near = difflib.get_close_matches(key, names, n=1)
        hint = (f"did you mean '{near[0]}'?" if near and key not in SCHEMA
                else f"parameters: {', '.join(names)}")
        if key in SCHEMA and not SCHEMA[key].param:
            hint = ("it is a static setting (each value compiles its own program): render "
                    f"each value with -D {key}=VALUE instead")
        raise InputError(f"--sweep: '{key}' is not a scalar parameter of this scene; {hint}",
                         sc.source)
    layers = [layer.name for layer in sc.layers]
    for value in (start, stop):
        check_value(key, value, f"--sweep {text}", layers)
    return key, np.linspace(start, stop, count)


def _sweeps(sc, text: str) -> bool:
    """Whether the --sweep `text`'s key is a scalar parameter of scene `sc`."""
    key = text.partition("=")[0].strip()
    return key in sc.params and getattr(sc.params[key], "ndim", 1) == 0


def _file_ending_named(value: str) -> str:
    """A -D value that names a file with its ending written `_ending` (`maps/m.png` →
    `maps/m_png`: the name read `..._skin.melanin_image-m.png.png`), so that the name
    still tells `m.png` from `m.exr` and a preset `skin` from a file `skin.json`."""
    from .outputs import FILE_SUFFIXES

    suffix = Path(value).suffix
    if suffix.lower() in FILE_SUFFIXES:
        return value[:-len(suffix)] + "_" + suffix[1:]
    return value


def _base_name(sc, overrides, room: int = 16) -> str:
    """The scene's output name: its (checked) name, then `_<key>-<value>` per override (a
    digest of them when that is long), unless one of them is `name=...`: then that name
    alone (a user naming a comparison's images got `espresso_look_D-13e6f4956f9c.png`).
    `room`: the most characters the outputs add after it (an extension, `_normal.png`, a
    sweep's `_sweep-NN_KEY-VALUE.png`). `InputError` naming the scene's `name` when even
    the digest leaves no room."""
    named = [item for item in overrides if item.partition("=")[0].strip() == "name"]
    base = check_name(sc.name, f"-D {named[-1]}" if named else sc.source, key="name")
    last = {}  # a key given twice: its last value, which is the one used (a trial)
    for item in overrides:
        key, _, value = (s.strip() for s in item.partition("="))
        last.pop(key, None)
        last[key] = value
    parts = [f"{slug(key)}-{slug(_file_ending_named(_name_value(key, value)))}"
             for key, value in last.items()
             if key != "name" and not named]  # `-D name=X` names the outputs X, nothing added
    suffix = "_".join(parts)

    def too_long(text):  # with `room` added, in characters and in UTF-8 bytes
        return (len(text) > MAX_NAME - room
                or len(text.encode("utf-8", "surrogatepass")) > MAX_NAME_BYTES - room)

    # many overrides, or a long name: a digest keeps runs apart and names short
    if len(suffix) > 120 or (suffix and too_long(f"{base}_{suffix}")):
        used = "\0".join(f"{key}={_name_value(key, value)}" for key, value in last.items())
        suffix = "D-" + hashlib.sha1(used.encode()).hexdigest()[:12]
    full = f"{base}_{suffix}" if suffix else base
    if too_long(full):
        raise InputError(f"the scene's name is {len(base)} characters; with what this run "
                         f"adds to it ({len(full) - len(base) + room} more: the -D values, "
                         "the sweep's values, the extension) the output names would be over "
                         f"{MAX_NAME} characters or {MAX_NAME_BYTES} bytes: shorten it (or "
                         "-D name=...)", f"-D {named[-1]}" if named else sc.source, key="name")
    return full


def _name_value(key: str, value: str) -> str:
    """A -D value as output names spell it: a number in its shortest exact form, so that
    `-D k=0.1`, `k=1e-1` and `k=0.10` (one render) name one file (a trial); `512.0` and
    `512` both `512`; a list of numbers as its numbers joined by `_` (`0,60,0` and
    `[0, 60, 0]` alike; a review). Anything else as given."""
    from .scene import parse_override as _parse_override

    def short(x) -> str:
        text = repr(float(x) + 0.0)  # -0.0 + 0.0 is 0.0: `=-0` named the file `k--0`
        return text[:-2] if text.endswith(".0") else text

    def number(x) -> bool:
        return isinstance(x, (int, float)) and not isinstance(x, bool)

    try:
        return short(float(value))
    except ValueError:
        pass
    parsed = _parse_override(f"{key}={value}")[1]
    if isinstance(parsed, list) and parsed and all(number(x) for x in parsed):
        return "_".join(short(x) for x in parsed)
    return value


def _reads_instead(sc, item: str, overrides) -> str:
    """`"; it reads KEY"` for an unused `-D` or `--sweep` item whose key's twin scene `sc`
    reads (`checks.read_instead`), else `""`: the end of the warning's parenthesis."""
    other = read_instead(sc, item, overrides)
    return f"; it reads {other}" if other else ""


def _sweep_suffixes(sweep, ext: str) -> list[str]:
    """What a sweep's files add to the scene's output name: `_sweep-NN_KEY-VALUE.EXT` per
    value (none without a sweep)."""
    if not sweep:
        return []
    (key, values), = sweep
    width = max(2, len(str(len(values))))
    # Six significant digits, more where two values would read alike (0.1:0.1000002:3 was
    # named 0.1 three times: a trial), up to the float's own shortest form.
    values = [float(v) + 0.0 for v in values]  # -0.0 + 0.0 is 0.0 (not named --0)
    digits = next((d for d in range(6, 17) if len({f"{v:.{d}g}" for v in values})
                   == len(set(values))), 17)
    return [f"_sweep-{i + 1:0{width}d}_{slug(key)}-{slug(f'{v:.{digits}g}')}.{ext}"
            for i, v in enumerate(values)]


def _render(args, run: _Run) -> int:
    import jax
    import numpy as np

    from . import maps
    from .scene import BUILTIN_SCENES, load_scene
    from .scene import parse_override as _parse_override

    if args.format == "exr" and not maps.exr_available():
        raise InputError("--format exr needs the OpenEXR bindings: pip install 'jaxskin[exr]'")
    output = "linear_rgba" if args.format == "exr" else "rgba" if args.alpha else "display"
    ext = "exr" if args.format == "exr" else "png"
    if len(args.sweep) > 1:
        raise InputError(f"one --sweep at a time for now (got {len(args.sweep)})")
    outputs = Outputs(args.output)
    # Everything checked before any output: every scene, its inputs, the sweep, memory,
    # the output names (distinct, safe, not an input).
    scenes = []
    named = [item for item in args.overrides if item.partition("=")[0].strip() == "name"]
    if named and len(args.scenes) > 1:  # every scene's outputs would take the one name
        raise InputError(f"gives all {len(args.scenes)} scenes of the command one name: render "
                         "one scene per command with -D name, or set name in each scene file",
                         f"-D {named[-1]}")
    for name in args.scenes:
        with reading(name):
            scenes.append(load_scene(name, args.overrides, flag="-D"))
        if name in BUILTIN_SCENES and Path(name).is_file():  # the built-in one wins (a trial)
            _say(f"jaxskin: warning: '{name}' is the built-in scene; the file {name} here is "
                 f"not read (give ./{name} for it)")
    _warn_repeated(args.overrides)
    # A sweep over a parameter some of the scenes have: the others are rendered once, with
    # a warning, as -D does (it stopped the batch; a trial). None has it: the error.
    swept = [bool(args.sweep) and _sweeps(sc, args.sweep[0]) for sc in scenes]
    unswept = [bool(args.sweep) and not here and any(swept) for here in swept]
    plans = []
    for sc, skip in zip(scenes, unswept, strict=True):
        sweep = [] if skip else [_parse_sweep(text, sc) for text in args.sweep]
        for (key, _), text in zip(sweep, args.sweep[:len(sweep)], strict=True):
            for item in args.overrides:
                if _parse_override(item)[0] == key:
                    raise InputError(f"--sweep {text} sets {key}, so -D {item} would be "
                                     "ignored (and named in every file); give one of them",
                                     key=key)
        count = cluster.SWEEP_BATCH if sweep else 1  # per batch: every batch is padded
        outputs.inputs += [Path(p) for p in check_scene(sc, count, args.overrides)]
        adds = [f".{ext}", ".glb" if args.glb else "", "_normal.png" if args.maps else "",
                *_sweep_suffixes(sweep, ext)]
        room = max(len(a.encode("utf-8")) for a in adds)  # the longest the outputs add
        plans.append((sc, sweep, _base_name(sc, args.overrides, room)))
    files = []
    for sc, sweep, base in plans:
        planned = {}
        if sweep:
            planned["sweep"] = [outputs.plan(base + suffix, sc.source)
                                for suffix in _sweep_suffixes(sweep, ext)]
        else:
            planned["image"] = outputs.plan(f"{base}.{ext}", sc.source)
        if args.glb:
            planned["glb"] = outputs.plan(f"{base}.glb", sc.source)
        if args.maps:
            for kind in ("height", "normal", "field"):
                planned[kind] = outputs.plan(f"{base}_{kind}.png", sc.source)
        files.append(planned)
    for sc, skip in zip(scenes, unswept, strict=True):  # after every check: warnings, not
        idle = idle_map_keys(sc)  # errors (-D serves every scene)
        for item in unused_overrides(sc, args.overrides):
            if _parse_override(item)[0] not in idle:  # an idle map's own line says more
                _say(f"jaxskin: warning: -D {item} changes nothing in scene {sc.name!r} "
                     f"(its material model or settings do not use it"
                     f"{_reads_instead(sc, item, args.overrides)})")
        if skip:
            key, _, spec = args.sweep[0].partition("=")
            hint = _reads_instead(sc, f"{key.strip()}={spec.split(':')[0]}", args.overrides)
            _say(f"jaxskin: warning: --sweep {args.sweep[0]} changes nothing in scene "
                 f"{sc.name!r} (not one of its parameters{hint}): it is rendered once, "
                 "unswept")
        for line in picture_warnings(sc):
            _say(f"jaxskin: warning: {line}")
    run.outputs.append(outputs)
    # The units of work: a scene's sweep in batches of cluster.SWEEP_BATCH values (one
    # compiled program per configuration), or the scene's one image; run here or on the
    # --cluster, the results come back in order and are written here.
    units, targets = [], []  # targets: (scene index, the unit's output paths)
    for i, ((sc, sweep, _), planned) in enumerate(zip(plans, files, strict=True)):
        params = jax.tree.map(np.asarray, sc.params)
        if sweep:
            (key, values), = sweep
            batches = cluster.sweep_batches(values)
            for k, batch in enumerate(batches):
                units.append(("images", sc.config, params, key, batch, output))
                targets.append((i, planned["sweep"][k * len(batch):(k + 1) * len(batch)]))
        else:
            units.append(("images", sc.config, params, None, None, output))
            targets.append((i, [planned["image"]]))
        if args.maps or args.glb:
            units.append(("maps", sc.config, params, args.glb))
            targets.append((i, None))
    seconds, n0 = [0.0] * len(plans), [0] * len(plans)
    rows, empty = [], set()
    with cluster.pool(args.cluster) as pool:
        run.stage = f"rendering {plans[0][0].name}"
        results = pool.map(cluster.render_unit, units, desc="render", unit="task")
        for k, ((i, paths), (result, dt)) in enumerate(zip(targets, results, strict=True)):
            sc, sweep, _ = plans[i]
            t0 = time.perf_counter()
            if k == 0 or targets[k - 1][0] != i:
                n0[i] = len(outputs.written)
            if paths is None:
                _write_maps(sc, files[i], outputs, result)
            else:
                for image, path in zip(result if sweep else [result], paths, strict=False):
                    bad = int(np.size(image) - np.count_nonzero(np.isfinite(image)))
                    if bad:  # a NaN is a black pixel in a PNG: never written as a picture
                        raise FitError(f"the render has {bad} non-finite values (NaN or "
                                       "infinity: a value outside what float32 holds?); "
                                       f"{path.name} not written", sc.source)
                    maps.write_render(image, path, args.format)
                    outputs.done(path)
                    if not np.any(image) and i not in empty:  # once per scene
                        empty.add(i)
                        _say(f"jaxskin: warning: {path.name}: {empty_picture(sc)}")
            seconds[i] += dt + time.perf_counter() - t0
            if k + 1 == len(targets) or targets[k + 1][0] != i:  # the scene's last unit
                config = sc.config
                size = f"{config.image}x{config.image_height or config.image}"
                rows.append((sc.name, size, len(outputs.written) - n0[i], seconds[i]))
            if k + 1 < len(targets):
                following = plans[targets[k + 1][0]][0].name
                run.stage = (f"making the maps of {following}" if targets[k + 1][1] is None
                             else f"rendering {following}")
    print(f"{'scene':<16} {'image':>9} {'files':>6} {'time s':>7}")
    for name, size, n, dt in rows:
        print(f"{name:<16} {size:>9} {n:>6} {dt:>7.2f}")
    _print_written(outputs)
    return 0


def _write_maps(sc, planned: dict, outputs: Outputs, result: dict) -> None:
    """Write a scene's texture-space maps (--maps) and GLB (--glb) from `result`
    (`cluster.scene_maps`: height, normals and the GLB's albedo, made here or on a worker)."""
    from . import maps, texture

    s = texture.setup(sc.config.texture)  # the mesh and texture space, for the mask and GLB
    if "glb" in planned:
        from .export import write_glb

        write_glb(s, result["albedo"], result["normals"], planned["glb"])
        outputs.done(planned["glb"])
    if "height" in planned:
        maps.write_height(result["height"], planned["height"])
        outputs.done(planned["height"])
        maps.write_normals(result["normals"], s.mask, planned["normal"])
        outputs.done(planned["normal"])
        maps.write_field_plot(s, planned["field"], f"{sc.name} ({s.mesh.name}): d1 (red), "
                              "d2 (green)", sc.config.rotate)
        outputs.done(planned["field"])


def _fit_brdf(args, run: _Run) -> int:
    from jaxskin import formats
    from jaxskin.fitting import brdf

    out = Path(args.output)
    if out.is_dir():
        raise InputError("-o: expected the file to write (OUT.json), but this is a folder",
                         out)
    if out.suffix.lower() != ".json":
        raise InputError(f"-o: expected a .json file name (the fitted lobes; the report is "
                         f"written beside it as .png), got {out.name!r}", out)
    outputs = Outputs(out.parent, [args.file], named_files=False)  # -o OUT.json: named
    out = outputs.plan(out.name, "the fit")
    report = None if args.no_report else outputs.plan(out.with_suffix(".png").name,
                                                      "the report")
    samples = brdf.read_samples(args.file)
    brdf.check_samples(samples, args.lobes)
    for note in samples.notes:
        print(f"jaxskin: note: {note}", file=sys.stderr)
    from . import resources

    resources.check_memory(resources.fit_brdf_bytes(len(samples.f), args.lobes, args.starts),
                           f"fitting {args.lobes} lobes x {args.starts} starts to "
                           f"{len(samples.f)} samples", args.file,
                           hint="use fewer --starts or --lobes")
    run.outputs.append(outputs)
    run.stage = "fitting"
    print(f"fitting {args.lobes} lobes x {args.starts} starts x 3 channels to "
          f"{len(samples.f)} samples ...", flush=True)
    t0 = time.perf_counter()
    with cluster.pool(args.cluster) as pool:
        result = brdf.fit(samples, lobes=args.lobes, starts=args.starts, seed=args.seed,
                          map_units=pool.mapper(desc="fit-brdf", unit="channel"))
    seconds = time.perf_counter() - t0
    stats = result.stats()
    formats.write_lafortune(result.params, out, fit={"source": Path(args.file).name, **stats})
    outputs.done(out)
    if report is not None:
        brdf.write_report(samples, result, report)
        outputs.done(report)
    print(f"{'channel':<8} {'rel. RMS error':>14} {'failed starts':>13} {'steps':>6}")
    for k, name in enumerate("RGB"):
        done = bool(result.converged[k, result.best[k]])  # the best start's own solver flag
        print(f"{name:<8} {result.rel_rms[k]:>14.2%} {stats['failed_starts'][k]:>13} "
              f"{stats['steps_of_best'][k]:>6}" + ("" if done else " (not converged: the "
                                                   "solver stopped at its step limit)"))
    print(f"wrote {out}" + ("" if report is None else f" and {report}") + f" ({seconds:.1f} s)")
    for line in brdf.fit_warnings(result):
        warnings.warn(line, stacklevel=1)
    return 0


def _fit_image(args, run: _Run) -> int:
    from jaxskin.fitting import image

    return image.run_command(args, run)


def _fit_skin(args, run: _Run) -> int:
    from jaxskin.fitting import skin

    return skin.command(args, run)


def _edit(args, run: _Run) -> int:
    from .editor import command

    return command(args, run)


def main(argv=None, early=None) -> int:
    """The `jaxskin` command: parse `argv` (default `sys.argv[1:]`), run the command, and
    return its exit code (0 done, 2 bad input, 1 failure, 130 SIGINT, 143 SIGTERM).
    `early`: signals noted before this was called (`_console`); until the command's own
    handlers are in place (`_signals`) it goes on noting them there, and they end the
    command before any work."""
    early = [] if early is None else early
    errors = {}  # a terminal that cannot show a name (an ASCII locale) gets its escapes, not
    for stream in (sys.stdout, sys.stderr):  # a UnicodeEncodeError; restored at the end
        with contextlib.suppress(AttributeError, ValueError):
            before = stream.errors
            stream.reconfigure(errors="backslashreplace")
            errors[stream] = before
    old = {}
    if threading.current_thread() is threading.main_thread():
        old = {sig: signal.signal(sig, lambda signum, frame: early.append(signum))
               for sig in _SIGNAL_ERRORS}
    try:
        return _main(argv, early)
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
        for stream, before in errors.items():
            with contextlib.suppress(AttributeError, ValueError):
                stream.reconfigure(errors=before)


def _main(argv, early: list) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    if early and args.command is None:  # no `_signals` on this path
        sig = early[0]
        word, code = _signal_words(sig)
        _say(f"jaxskin: {word} ({signal.Signals(sig).name}) while starting; no file was "
             "written")
        return code
    if args.command is None:  # the help, on stderr, and the exit code of a usage error
        parser.print_help(sys.stderr)
        return 2
    if args.command != "list":
        _enable_compilation_cache()
    run = _Run("listing" if args.command == "list" else "checking the inputs")
    # `list` too: it loads JAX and the spectral tables (1-4 s), where a signal was only
    # noted and the list printed on to exit 0 (a review)
    commands = {"calibrate": _calibrate, "fit-brdf": _fit_brdf, "render": _render,
                "fit-skin": _fit_skin, "edit": _edit, "fit-image": _fit_image, "list": _list}
    with _signals(), _pipe_safe_stdout():
        try:
            _pending.extend(early)  # what arrived before `_signals`: ends it here
            early.clear()
            _raise_pending()
            code = commands[args.command](args, run)
            _raise_pending()
            return code
        except InputError as e:
            _say(f"jaxskin: error: {e}")
            return EXIT_INPUT
        except FitError as e:  # valid input, a fit that failed: says so, nothing written for it
            _say(f"jaxskin: error: {e}; {run.finished()}")
            return EXIT_FAILURE
        except KeyboardInterrupt:
            _say(f"jaxskin: interrupted (SIGINT) while {run.stage}; {run.finished()}")
            return EXIT_SIGINT
        except _Terminated:
            _say(f"jaxskin: terminated (SIGTERM) while {run.stage}; {run.finished()}")
            return EXIT_SIGTERM
        except Exception as e:  # noqa: BLE001  (anything else: a bug, memory, the disk)
            if args.debug:
                raise
            what = " ".join(f"{e.__class__.__name__}: {e}".split())[:300]
            _say(f"jaxskin: error: {args.command} failed unexpectedly while {run.stage} "
                 f"({what}); {run.finished()}; run again with --debug for the traceback")
            return EXIT_FAILURE


class _PipeSafe:
    """Standard output that a closed pipe (`jaxskin calibrate … | head -2`) does not stop:
    what is printed after the reader went is dropped, the work goes on and its files are
    written (a BrokenPipeError from a progress line ended calibrate with exit 1)."""

    def __init__(self, stream):
        self._stream, self._broken = stream, False

    def write(self, text):
        if not self._broken:
            try:
                return self._stream.write(text)
            except BrokenPipeError:
                self._gone()
        return len(text)

    def flush(self):
        if not self._broken:
            try:
                self._stream.flush()
            except BrokenPipeError:
                self._gone()

    def _gone(self):
        self._broken = True
        with contextlib.suppress(OSError, ValueError):  # the interpreter's last flush too
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, self._stream.fileno())
            os.close(devnull)

    def __getattr__(self, name):
        return getattr(self._stream, name)


@contextlib.contextmanager
def _pipe_safe_stdout():
    old = sys.stdout
    sys.stdout = _PipeSafe(old)
    try:
        yield
    finally:
        sys.stdout = old


def _say(line: str) -> None:
    """One line on stderr, whatever the message holds: newlines become spaces, and any other
    control character its escape (`-D name=` with U+009B, a terminal's escape, was echoed
    raw: a trial), so that a message cannot drive the terminal."""
    line = " ".join(line.split()) if len(line.splitlines()) > 1 else line
    print("".join(ascii(c)[1:-1] if _control(c) else c for c in line), file=sys.stderr,
          flush=True)


if __name__ == "__main__":
    sys.exit(main())
