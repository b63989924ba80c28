"""Input errors, atomic output files and the shipped data folder.

Everything that reads user files raises `InputError` with one line naming the file, the
line or key, and what was expected; the CLI prints it and exits with code 2. Everything that
writes goes through `atomic_write`, so no half-written file is ever left behind.
"""

from __future__ import annotations

import contextlib
import importlib.resources
import os
import stat
import tempfile
from pathlib import Path

__all__ = ["FitError", "InputError", "atomic_write", "check_regular", "data_dir", "real_path"]


class InputError(ValueError):
    """Bad user input, reported as one line: `file:line: column 'c': message` (or `key 'k'`).

    **Arguments:**

    - `message`: what is wrong and what was expected.
    - `path`: the file (or `None`).
    - `line`: 1-based line number in the file (or `None`).
    - `column`: the CSV column (or `None`).
    - `key`: the key, for JSON and scene files (or `None`).
    """

    def __init__(self, message: str, path=None, line: int | None = None, column=None,
                 key=None):
        self.path, self.line, self.column, self.key = path, line, column, key
        self.message = message
        super().__init__(_located(message, path, line, column, key))


def _located(message, path=None, line=None, column=None, key=None) -> str:
    """`file:line: column 'c': message` (or `key 'k'`), leaving out what is None."""
    where = "" if path is None else str(path)
    if line is not None:
        where += f":{line}"
    named = f"column '{column}'" if column is not None else None
    named = f"key '{key}'" if key is not None else named
    return ": ".join([*(p for p in (where, named) if p), message])


class FitError(RuntimeError):
    """A fit that failed on valid input (e.g. a non-finite result), one line like
    `InputError`'s (same arguments); the CLI prints it and exits with code 1, not 2."""

    def __init__(self, message: str, path=None, line: int | None = None, column=None,
                 key=None):
        self.path, self.line = path, line
        super().__init__(_located(message, path, line, column, key))


# What `os.stat` says a path is when it is not a regular file, for `check_regular`.
KINDS = ((stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
         (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def check_regular(path, expected: str = "a file") -> None:
    """`InputError` naming `path` unless it is a regular file (after links): a FIFO blocks
    `open` until a writer comes (the command hung, Ctrl-C the only way out), a device or a
    pipe has no end (/dev/zero). `os.stat` only, nothing opened. A missing file raises
    `FileNotFoundError` as `open` would, for the caller's own message."""
    mode = os.stat(path).st_mode
    if stat.S_ISDIR(mode):
        raise InputError(f"is a folder, expected {expected}", path)
    if not stat.S_ISREG(mode):
        kind = next((k for test, k in KINDS if test(mode)), "not a file")
        raise InputError(f"not a regular file ({kind}): expected {expected}", path)


def real_path(path) -> Path:
    """`path` absolute, its links followed (`os.path.realpath`): unlike `Path.resolve`,
    a link loop is no exception here; the file's own check then says what it is."""
    return Path(os.path.realpath(path))


@contextlib.contextmanager
def atomic_write(path, mode: str = "wb"):
    """Open a temporary file beside `path`; rename it onto `path` only if the block succeeds.

    **Arguments:**

    - `path`: the final file name.
    - `mode`: `"wb"` or `"w"`.

    **Returns:** a context manager yielding the open temporary file.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, mode) as f:
            yield f
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give what open() would
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def data_dir() -> Path:
    """The shipped data folder, `jaxskin.data`: meshes, scenes, spectra, materials, examples.

    Read through `importlib.resources`, so it is found the same way in a regular install
    (inside the wheel), an editable install (the repository's `data/`) and a checkout.
    """
    root = importlib.resources.files("jaxskin.data")
    path = Path(str(root))
    if not path.is_dir():  # a zipped install: jaxskin needs real files for trimesh and numpy
        raise InputError("jaxskin's data is not a folder on disk; install jaxskin unzipped "
                         "(pip does)", path)
    return path
