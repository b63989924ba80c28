"""A command's process: its exit codes, the record of the files it has written (for the
last line after a failure or a signal), and SIGINT / SIGTERM.

While a command runs (`handling_signals`), SIGINT raises KeyboardInterrupt and SIGTERM
`Terminated` where the signal arrives, so that `io.atomic_write` removes its temporary
file and the command ends with one line naming the files that are complete. Where an
exception raised there would be lost, the signal is held and raised at the next stage
change (`Run.stage`) or the command's end: inside the garbage collector's callbacks or a
finaliser, where Python prints the exception and drops it; inside an import, which some
libraries wrap in `except BaseException` (trimesh's optional imports); and while an
asyncio event loop runs (`holding_signals`), which an exception raised anywhere in it can
leave half made or half closed.

Once the command has ended (`finish`: its work done or its last line chosen) a signal is
only noted: raised in the few lines that follow (putting the terminal back, restoring the
handlers) it would leave as a traceback, with the command's work complete.
"""

from __future__ import annotations

import contextlib
import gc
import os
import signal
import sys
import threading
import warnings
from typing import TYPE_CHECKING, NoReturn

from ._terminal import say, warning_line

if TYPE_CHECKING:
    from ..outputs import Outputs

__all__ = ["EXIT_FAILURE", "EXIT_INPUT", "EXIT_SIGINT", "EXIT_SIGTERM", "SIGNAL_ERRORS", "Run",
           "Terminated", "exit_now", "finish", "handling_signals", "holding_signals",
           "pending_signal", "print_written", "raise_pending", "raise_received",
           "signal_words", "signals_received"]

EXIT_FAILURE, EXIT_INPUT, EXIT_SIGINT, EXIT_SIGTERM = 1, 2, 130, 143

# The last line after a failure or a signal names at most this many of the files written
# (the last ones): a long sweep stopped halfway would otherwise print a line of kilobytes.
SHOWN_NAMES = 8


class Terminated(BaseException):
    """SIGTERM, raised in the main thread like KeyboardInterrupt is for SIGINT."""


SIGNAL_ERRORS = {signal.SIGINT: KeyboardInterrupt, signal.SIGTERM: Terminated}
pending: list[int] = []  # a signal whose exception could not be raised where it arrived
received: list[int] = []  # every signal the command's handler took
collecting = [False]  # the garbage collector is running (and calling JAX's callback)
holding = [False]  # every signal is held (`holding_signals`)
finished = [False]  # the command has ended: a signal is only noted (`finish`)


class Run:
    """What a command has written so far (`outputs`) and what it is doing (`stage`): for the
    last line after a failure or a signal."""

    def __init__(self, stage: str = "checking the inputs"):
        self.outputs: list[Outputs] = []
        self._stage = stage

    @property
    def stage(self) -> str:
        """What the command is doing, for the last line; setting it is also where a signal
        held back by `handling_signals` is raised."""
        return self._stage

    @stage.setter
    def stage(self, text: str) -> None:
        raise_pending()
        self._stage = text

    def finished(self) -> str:
        """The files complete so far, for the last line: each once, where it was last
        written (the editor saves one name again), the last `SHOWN_NAMES` named."""
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


def print_written(outputs: Outputs) -> None:
    """The command's closing lines on stdout: `wrote N file(s) to DIR/:`, then each file."""
    print(f"wrote {len(outputs.written)} file(s) to {outputs.folder}/:")
    for path in outputs.written:
        print(f"  {path}")


def _gc_start(phase, info):
    if phase == "start":
        collecting[0] = True


def _gc_stop(phase, info):
    if phase == "stop":
        collecting[0] = False


def _on_signal(signum, frame):
    """Raise KeyboardInterrupt / Terminated where the signal arrived, unless it would be
    lost there (the module's docstring): then it is kept, and raised at the next
    `raise_pending` or taken by `pending_signal`."""
    received.append(signum)
    if finished[0]:  # the command has ended: its exit code and last line stand
        return
    if collecting[0] or holding[0] or _held_back(frame):
        pending.append(signum)
        return
    raise SIGNAL_ERRORS[signum]()


def _held_back(frame) -> bool:
    """Whether `frame` is in a finaliser or JAX's collector callback, or inside an import."""
    if frame is not None and frame.f_code.co_name in ("__del__", "_xla_gc_callback"):
        return True
    while frame is not None:
        if frame.f_code.co_filename.startswith("<frozen importlib"):
            return True
        frame = frame.f_back
    return False


@contextlib.contextmanager
def holding_signals():
    """Hold every signal (`pending_signal` takes it) for the duration: for an asyncio event
    loop, which an exception raised anywhere in it can leave half made or half closed (a
    loop without its self-pipe, whose finaliser prints after the command's last line)."""
    holding[0] = True
    try:
        yield
    finally:
        holding[0] = False


def finish() -> None:
    """The command has ended (its work done, or its last line about to be said): from here
    to the end of `handling_signals` a signal is noted, not raised."""
    finished[0] = True


def signals_received() -> int:
    """How many signals the command has received."""
    return len(received)


def signal_words(sig: int) -> tuple[str, int]:
    """`("interrupted", 130)` for SIGINT, `("terminated", 143)` for SIGTERM."""
    return ("interrupted", EXIT_SIGINT) if sig == signal.SIGINT else ("terminated", EXIT_SIGTERM)


def exit_now(run: Run) -> NoReturn:
    """For a second signal while a command waits on work a signal cannot stop (the editor's
    render in its worker thread): the command's last line, then the process ends at once,
    not waiting for that work (it writes nothing; a Save caught halfway may leave its
    temporary file)."""
    sig = received[-1]
    word, code = signal_words(sig)
    say(f"jaxskin: {word} ({signal.Signals(sig).name}) while {run.stage}; {run.finished()}")
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def pending_signal() -> bool:
    """Whether a signal is held back; it is taken off the list (still in
    `raise_received`'s)."""
    if pending:
        pending.clear()
        return True
    return False


def raise_received() -> None:
    """Raise the last signal the command received, if any: for a command whose library
    swallows the exception a signal raised (aiohttp's `run_app` returns on
    KeyboardInterrupt), so that it still ends with 130 / 143 and its line."""
    if received:
        raise SIGNAL_ERRORS[received[-1]]()


def raise_pending() -> None:
    """Raise a signal that arrived where it could not be raised (the module's docstring)."""
    if pending:
        raise SIGNAL_ERRORS[pending.pop(0)]()


@contextlib.contextmanager
def handling_signals():
    """SIGINT → KeyboardInterrupt, SIGTERM → Terminated, for the duration of a command
    (atomic_write removes its temporary file on either), and Python's warnings as one line
    each; the old handlers come back after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old_format = warnings.formatwarning
    warnings.formatwarning = warning_line
    old = {sig: signal.getsignal(sig) for sig in SIGNAL_ERRORS}
    pending.clear()
    received.clear()
    finished[0] = False
    # First and last of the collector's callbacks, so that JAX's (which runs Python code in
    # both phases) sits between them.
    gc.callbacks.insert(0, _gc_start)
    gc.callbacks.append(_gc_stop)
    for sig in SIGNAL_ERRORS:
        signal.signal(sig, _on_signal)
    try:
        yield
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
        for callback in (_gc_start, _gc_stop):
            if callback in gc.callbacks:
                gc.callbacks.remove(callback)
        collecting[0] = False
        warnings.formatwarning = old_format
