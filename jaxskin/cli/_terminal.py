"""What the command line prints: one line per message on stderr, whatever it holds, and
a standard output that a closed pipe does not stop."""

from __future__ import annotations

import contextlib
import os
import sys

from ..outputs import control

__all__ = ["escaped", "escaped_streams", "note", "pipe_safe_stdout", "say", "warn",
           "warning_line"]


def escaped(text: str) -> str:
    """Each control character of `text` as its escape (`\\x1b`, `\\u202e`), so that a
    message (a file name with a terminal's escape in it, say) cannot drive the terminal."""
    return "".join(ascii(c)[1:-1] if control(c) else c for c in text)


def say(line: str) -> None:
    """One line on stderr, whatever the message holds: newlines become spaces, and any other
    control character its escape (`escaped`)."""
    line = " ".join(line.split()) if len(line.splitlines()) > 1 else line
    print(escaped(line), file=sys.stderr, flush=True)


def warn(text: str) -> None:
    """`jaxskin: warning: TEXT`, one line on stderr (`say`)."""
    say(f"jaxskin: warning: {text}")


def note(text: str) -> None:
    """`jaxskin: note: TEXT`, one line on stderr (`say`)."""
    say(f"jaxskin: note: {text}")


def warning_line(message, category, filename, lineno, line=None) -> str:
    """A Python warning as one line, `jaxskin: warning: …` (not Python's two with the
    source), its control characters escaped as `warn` escapes them:
    `warnings.formatwarning` while a command runs, for the library's warnings."""
    return f"jaxskin: warning: {escaped(' '.join(str(message).split()))}\n"


class PipeSafe:
    """Standard output that a closed pipe (`jaxskin calibrate … | head -2`) does not stop:
    what is printed after the reader went is dropped, the work goes on and its files are
    written."""

    def __init__(self, stream):
        self._stream, self._broken = stream, False

    def write(self, text):
        """Write `text`, or drop it once the reader has gone."""
        if not self._broken:
            try:
                return self._stream.write(text)
            except BrokenPipeError:
                self._gone()
        return len(text)

    def flush(self):
        """Flush, unless the reader has gone."""
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
def pipe_safe_stdout():
    """`sys.stdout` is a `PipeSafe` for the duration."""
    old = sys.stdout
    sys.stdout = PipeSafe(old)
    try:
        yield
    finally:
        sys.stdout = old


@contextlib.contextmanager
def escaped_streams():
    """stdout and stderr write a character they cannot encode (a name in an ASCII locale)
    as its escape, not a UnicodeEncodeError; restored after."""
    errors = {}
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(AttributeError, ValueError):
            before = stream.errors
            stream.reconfigure(errors="backslashreplace")
            errors[stream] = before
    try:
        yield
    finally:
        for stream, before in errors.items():
            with contextlib.suppress(AttributeError, ValueError):
                stream.reconfigure(errors=before)
