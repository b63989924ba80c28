"""The `jaxskin` command's entry point: takes SIGINT and SIGTERM from its first moment to
its last.

Running a command imports JAX (about a second). A signal in that second would go Python's
default way: a traceback, an `ImportError` from an extension interrupted while it loaded, a
crash, or — raised inside JAX's garbage-collector callback, where Python prints and drops
it — no effect at all, the command running to the end with exit 0. Here a signal before
the command line's own handlers is only noted, and `cli.main` ends with 130 / 143 and its
one line before doing any work.

After the command (its exit code known, its last line said) the process still runs JAX's
exit handlers (`clean_up`: the backends and caches let go, a second or more after a
sweep) and the interpreter's teardown. Python's own handler would raise KeyboardInterrupt
there (a traceback from `cache.cache_clear()`, the exit code still 0); here a signal ends
the process at once with the command's exit code (`os._exit`, the streams flushed), and
during the teardown, where no Python handler runs any more, signals are ignored.

A command a signal stopped (130 / 143) ends the same way, at once, without the exit
handlers and the teardown: the user asked it to stop, its line is said, its files are
complete or removed, and a compile interrupted inside XLA leaves objects whose teardown
can crash (an exit code of 139 was seen now and then after a signal in the first compile).
"""

import atexit
import os
import signal
import sys

SIGNALS = (signal.SIGINT, signal.SIGTERM)


def main(argv=None) -> int:
    """The `jaxskin` script: note SIGINT and SIGTERM, import the command line, run it."""
    early: list[int] = []
    old = {sig: signal.signal(sig, lambda signum, frame: early.append(signum))
           for sig in SIGNALS}
    # Registered before JAX is imported: atexit runs last what was registered first.
    atexit.register(_ignore_signals)
    try:
        from jaxskin import cli  # JAX and the rest: about a second

        code = cli.main(argv, early=early)
    except BaseException:  # --debug's traceback, or a usage error's SystemExit: Python's way
        for sig, handler in old.items():
            signal.signal(sig, handler)
        atexit.unregister(_ignore_signals)
        raise
    if code in (130, 143):  # stopped by a signal: its line is said, nothing is left to do
        _exit(code)
    for sig in SIGNALS:  # the command has ended: a signal now ends the process, with its code
        signal.signal(sig, lambda signum, frame, code=code: _exit(code))
    return code


def _exit(code: int) -> None:
    """End the process now with `code`, what is buffered written out first."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:  # noqa: BLE001, S110  (a closed pipe: nothing more to say)
            pass
    os._exit(code)


def _ignore_signals() -> None:
    """The last exit handler: from here on the interpreter tears itself down, where Python
    handlers no longer run (a signal would kill the process, 130 with no line)."""
    for sig in SIGNALS:
        signal.signal(sig, signal.SIG_IGN)


if __name__ == "__main__":
    sys.exit(main())
