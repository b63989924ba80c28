"""The `jaxskin` command's entry point: takes SIGINT and SIGTERM from its first moment.

Running a command imports JAX (about a second). A signal in that second would go Python's
default way: a traceback, an `ImportError` from an extension interrupted while it loaded, a
crash, or — raised inside JAX's garbage-collector callback, where Python prints and drops
it — no effect at all, the command running to the end with exit 0. Here a signal before
the command line's own handlers is only noted, and `cli.main` ends with 130 / 143 and its
one line before doing any work.
"""

import signal
import sys


def main(argv=None) -> int:
    """The `jaxskin` script: note SIGINT and SIGTERM, import the command line, run it."""
    early: list[int] = []
    old = {sig: signal.signal(sig, lambda signum, frame: early.append(signum))
           for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        from jaxskin import cli  # JAX and the rest: about a second

        return cli.main(argv, early=early)
    finally:  # Python's own again for the exit (atexit, threads joined): not swallowed
        for sig, handler in old.items():
            signal.signal(sig, handler)


if __name__ == "__main__":
    sys.exit(main())
