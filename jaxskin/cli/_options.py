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


def saunderson_pair(text: str) -> tuple[float, float]:
    """`--saunderson K1,K2`: two numbers in [0, 1)."""
    parts = text.replace(" ", "").split(",")
    try:
        k = tuple(float(p) for p in parts)
    except ValueError:
        k = ()
    if len(k) != 2 or not all(math.isfinite(v) and 0 <= v < 1 for v in k):
        raise argparse.ArgumentTypeError(f"expected K1,K2: two numbers in [0, 1) such as "
                                         f"0.04,0.6, got {text!r}")
    return k


def saunderson(p, what: str) -> None:
    """The `--saunderson K1,K2` option (calibrate, match); `what` says what it does there."""
    p.add_argument("--saunderson", type=saunderson_pair, metavar="K1,K2",
                   help="Saunderson's surface correction for readings that include the "
                   "surface's reflection (specular included, SCI): R_m = K1 + (1-K1)(1-K2) R "
                   "/ (1 - K2 R), K1 the external (about 0.04; 0 for SCE), K2 the internal "
                   f"reflection (about 0.4-0.6); {what}. Default: none")

