"""The `jaxskin` command: its parser, assembled from one module per command, and `main`,
which runs a command inside the process's handling of signals, errors and exit codes."""

from __future__ import annotations

import argparse
import signal
import sys
import threading

from .. import __version__, compile_cache
from ..io import FitError, InputError
from . import (
    _calibrate,
    _edit,
    _fit_brdf,
    _fit_image,
    _fit_skin,
    _list,
    _match,
    _mix,
    _render,
    _skin_maps,
)
from ._options import Parser
from ._process import (
    EXIT_FAILURE,
    EXIT_INPUT,
    EXIT_SIGINT,
    EXIT_SIGTERM,
    SIGNAL_ERRORS,
    Run,
    Terminated,
    finish,
    handling_signals,
    pending,
    raise_pending,
    signal_words,
)
from ._terminal import escaped_streams, pipe_safe_stdout, say

__all__ = ["COMMANDS", "main", "parser"]

# Each command's module: `add_parser(sub)` and `run(args, record) -> exit code`, in the
# order `jaxskin --help` lists them.
COMMANDS = {"list": _list, "calibrate": _calibrate, "mix": _mix, "match": _match,
            "render": _render, "fit-image": _fit_image, "fit-brdf": _fit_brdf,
            "fit-skin": _fit_skin, "skin-maps": _skin_maps, "edit": _edit}


def parser() -> argparse.ArgumentParser:
    """The `jaxskin` command's parser, every command's options in it."""
    p = Parser(
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
    for command in COMMANDS.values():
        command.add_parser(sub)
    return p


def main(argv=None, early=None) -> int:
    """The `jaxskin` command: parse `argv` (default `sys.argv[1:]`), run the command, and
    return its exit code (0 done, 2 bad input, 1 failure, 130 SIGINT, 143 SIGTERM).
    `early`: signals noted before this was called (`jaxskin._console`); until the command's
    own handlers are in place (`handling_signals`) it goes on noting them there, and they
    end the command before any work."""
    early = [] if early is None else early
    old = {}
    with escaped_streams():
        if threading.current_thread() is threading.main_thread():
            old = {sig: signal.signal(sig, lambda signum, frame: early.append(signum))
                   for sig in SIGNAL_ERRORS}
        try:
            return _main(argv, early)
        finally:
            for sig, handler in old.items():
                signal.signal(sig, handler)


def _main(argv, early: list) -> int:
    p = parser()
    args = p.parse_args(argv)
    if early and args.command is None:  # no `handling_signals` on this path
        sig = early[0]
        word, code = signal_words(sig)
        say(f"jaxskin: {word} ({signal.Signals(sig).name}) while starting; no file was "
            "written")
        return code
    if args.command is None:  # the help, on stderr, and the exit code of a usage error
        p.print_help(sys.stderr)
        return EXIT_INPUT
    if args.command != "list":
        compile_cache.enable()
    # `list` too takes signals as a stage: it loads JAX and the spectral tables (1-4 s)
    record = Run("listing" if args.command == "list" else "checking the inputs")
    try:
        return _run(args, record, early)
    except (KeyboardInterrupt, Terminated) as e:  # in the instant before an ending's `finish`
        sig = signal.SIGINT if isinstance(e, KeyboardInterrupt) else signal.SIGTERM
        word, code = signal_words(sig)
        say(f"jaxskin: {word} ({sig.name}) while {record.stage}; {record.finished()}")
        return code


def _run(args, record: Run, early: list) -> int:
    """The command inside the handling of signals: every ending calls `finish` first, so
    that a signal after it (in the ending's line, or while the handlers are restored) is
    noted, not raised as a traceback."""
    with handling_signals(), pipe_safe_stdout():
        try:
            pending.extend(early)  # what arrived before `handling_signals`: ends it here
            early.clear()
            raise_pending()
            code = COMMANDS[args.command].run(args, record)
            raise_pending()
            finish()  # the work is complete: a signal from here on changes nothing
            return code
        except InputError as e:
            finish()
            say(f"jaxskin: error: {e}")
            return EXIT_INPUT
        except FitError as e:  # valid input, a fit that failed: says so, nothing written for it
            finish()
            say(f"jaxskin: error: {e}; {record.finished()}")
            return EXIT_FAILURE
        except KeyboardInterrupt:
            finish()
            say(f"jaxskin: interrupted (SIGINT) while {record.stage}; {record.finished()}")
            return EXIT_SIGINT
        except Terminated:
            finish()
            say(f"jaxskin: terminated (SIGTERM) while {record.stage}; {record.finished()}")
            return EXIT_SIGTERM
        except Exception as e:  # noqa: BLE001  (anything else: a bug, memory, the disk)
            finish()
            if args.debug:
                raise
            what = " ".join(f"{e.__class__.__name__}: {e}".split())[:300]
            say(f"jaxskin: error: {args.command} failed unexpectedly while {record.stage} "
                f"({what}); {record.finished()}; run again with --debug for the traceback")
            return EXIT_FAILURE
