"""The parser's parts that every command shares: one-line errors, checked numbers, and the
options that several commands take (`-D`, `--seed`, `--no-report`; `--cluster` is
`jaxskin.cluster.add_option`)."""

from __future__ import annotations

import argparse
import math

from ._process import EXIT_INPUT

__all__ = ["Parser", "no_report", "number", "overrides", "seed"]


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors: `jaxskin: error: …`, exit 2 (no usage block)."""

    def error(self, message):
        """Print `jaxskin: error: COMMAND: MESSAGE (see … --help)` and exit 2."""
        command = self.prog.removeprefix("jaxskin").strip()
        self.exit(EXIT_INPUT, f"jaxskin: error: {command + ': ' if command else ''}{message} "
                  f"(see {self.prog} --help)\n")


def number(kind=float, lo=None, hi=None, above=None):
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


def overrides(p, help: str) -> None:
    """`-D KEY=VALUE` (repeatable, into `args.overrides`): a scene value changed."""
    p.add_argument("-D", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help=help)


def seed(p) -> None:
    """`--seed`: the seed of a fit's random starts."""
    p.add_argument("--seed", type=number(int, 0, 2147483647), default=0,
                   help="seed of the random starts, 0-2147483647 (0)")


def no_report(p, what: str) -> None:
    """`--no-report`: write the fit's `what` (JSON, CSV) only, not its PNG report."""
    p.add_argument("--no-report", action="store_true", help=f"write the {what} only, no PNG")
