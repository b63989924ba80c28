"""Where a command writes: checked output folders, safe file names, inputs never overwritten.

The rules every command follows, all checked before any work:

- The output folder exists or can be created, is a folder (not a file) and is writable.
- An output name is one safe path component: no separator, no `..`, no leading dot, no
  control character, at most 200 characters and 240 bytes in UTF-8. A scene name that
  breaks this is refused (exit 2), never silently changed; the parts jaxskin adds itself
  (override and sweep suffixes) are sanitised by `slug`.
- Every output path lies directly inside the output folder (checked on resolved paths).
- No output is the same file as an input of the run (`os.path.samefile`, links resolved).
"""

from __future__ import annotations

import hashlib
import os
import re
import tempfile
import unicodedata
from pathlib import Path

from .io import InputError

__all__ = ["Outputs", "check_folder", "check_name", "control", "slug"]

MAX_NAME = 200
# A file name's bytes (UTF-8) at most: file systems allow 255, and `io.atomic_write`'s
# temporary file beside it adds 14 ("." + name + ".XXXXXXXX.tmp").
MAX_NAME_BYTES = 240
_UNSAFE = re.compile(r"[^A-Za-z0-9._+=-]+")


# Bidirectional controls reorder how a name is shown (U+202E made "x\u202eyz.png" read
# "xgnp.zy"), so they can disguise a file name; the invisible zero-width space, word
# joiner and byte-order mark make two names that look alike.
_HIDDEN = frozenset("\u061c\u200e\u200f\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068"
                    "\u2069\u200b\u2060\ufeff")


def control(text: str) -> bool:
    """Whether `text` holds a control character: C0 and C1 controls (a newline, a NUL, DEL,
    U+009B, a terminal's escape), line and paragraph separators, bidirectional controls and
    invisible spaces (`_HIDDEN`). Zero-width joiners (U+200C, U+200D) are letters' business
    in some scripts, and a file name's bytes that are not UTF-8 (read as surrogates: a
    Latin-1 `café.toml`) name files as well as any: both allowed."""
    return any(unicodedata.category(c) in ("Cc", "Zl", "Zp") or c in _HIDDEN for c in text)


def check_name(name: str, where=None, key: str | None = "name") -> str:
    """`name` if it is one safe path component, else an `InputError` saying why."""
    why = None
    if not isinstance(name, str) or not name:
        why = "is empty"
    elif control(name):
        why = "contains a control character"
    elif name != name.strip():  # " " wrote " _texture.size-64.png"
        why = "starts or ends with a space"
    elif "/" in name or "\\" in name or (os.altsep and os.altsep in name):
        why = "contains a path separator"
    elif name in (".", "..") or name.startswith("."):
        why = "starts with a dot"
    elif len(name) > MAX_NAME:
        why = f"is longer than {MAX_NAME} characters"
    elif len(name.encode("utf-8", "surrogatepass")) > MAX_NAME_BYTES:
        why = (f"is {len(name.encode('utf-8', 'surrogatepass'))} bytes in UTF-8, over the "
               f"{MAX_NAME_BYTES} a file name may take here (letters such as é take 2 bytes, "
               "most CJK 3)")
    if why is not None:
        raise InputError(f"an output name must be one plain file name (no '/' or '\\', no "
                         f"leading dot, control characters or spaces at the ends); {name!r} "
                         f"{why}",
                         where, key=key)
    return name


def slug(text: str) -> str:
    """`text` made safe for a file name: runs of characters other than letters, digits and
    `._+=-` become `_`, leading dots are dropped; long results keep a hash of the whole."""
    s = _UNSAFE.sub("_", str(text)).lstrip(".") or "_"
    if len(s) > 60:
        s = s[:50] + "_" + hashlib.sha1(str(text).encode()).hexdigest()[:8]
    return s


# The endings of the files the commands write or read: an -o folder still to be made with
# one of them is meant as a file (`calibrate -o fit.json` would make a folder 'fit.json').
FILE_SUFFIXES = {".json", ".png", ".exr", ".glb", ".csv", ".toml", ".npz", ".jpg", ".jpeg"}


def check_folder(path, option: str = "-o", named_files: bool = True) -> Path:
    """An output folder that exists (a writable folder) or can be created; nothing is
    created (a probe file in an existing folder is removed at once). `named_files`: the
    command names the files in it (calibrate, render, ...), so a folder still to be made
    whose name ends like a file (`fit.json`) was meant as a file and is refused; a name
    written with a trailing `/` is taken as a folder."""
    if not str(path).strip():
        raise InputError(f"{option}: expected an output folder, got an empty name "
                         "(use . for the current folder)")
    slash = str(path).endswith(("/", os.sep))  # `-o fit.json/`: a folder, said so
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InputError(f"{option}: expected a folder, but this is a file", path)
    try:  # a link that leads nowhere: a missing target, or a loop (exit 1 after the work)
        os.stat(path)
    except FileNotFoundError:
        if os.path.islink(path):
            raise InputError(f"{option}: a link to {os.readlink(path)!r}, which does not "
                             "exist; create it or give another folder", path) from None
    except OSError as e:
        raise InputError(f"{option}: cannot use this folder ({e.strerror or e.__class__.__name__})",
                         path) from None
    if (named_files and not slash and not os.path.lexists(path)
            and path.suffix.lower() in FILE_SUFFIXES):  # would make a folder 'fit.json'
        raise InputError(f"{option}: expected the folder to write into, got a file name "
                         f"({path.name!r}; the outputs are named after the inputs or scenes): "
                         f"give a folder, or '{path.name}/' to make a folder of that name",
                         path)
    probe = path
    while not probe.exists():  # the nearest existing ancestor must take a new folder
        if os.path.islink(probe):  # -o dangling/sub: the link leads nowhere (exit 1 after)
            raise InputError(f"{option}: {probe} is a link to {os.readlink(probe)!r}, which "
                             "does not exist; create it or give another folder", path)
        if probe.parent == probe:
            break
        probe = probe.parent
    if not probe.is_dir():
        raise InputError(f"{option}: cannot create the folder: {probe} is a file", path)
    new = path.relative_to(probe) if probe != path else Path()
    if control(str(new)):  # a newline would make a folder
        raise InputError(f"{option}: a folder to create must not contain control characters "
                         f"(a newline?); got {str(path)!r}")
    try:
        if probe == path:
            fd, tmp = tempfile.mkstemp(dir=path, prefix=".jaxskin-probe-")
            os.close(fd)
            os.unlink(tmp)
        else:
            os.rmdir(tempfile.mkdtemp(dir=probe, prefix=".jaxskin-probe-"))
    except OSError as e:
        raise InputError(f"{option}: cannot write here ({e.strerror or e.__class__.__name__})",
                         path) from None
    return path


def _same(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


class Outputs:
    """The files a run will write into one folder, checked up front, and those written.

    **Arguments:**

    - `folder`: the output folder (checked with `check_folder`).
    - `inputs`: every file the run reads.
    """

    def __init__(self, folder, inputs=(), option: str = "-o", named_files: bool = True):
        self.folder = check_folder(folder, option, named_files)
        self.option = option
        self.inputs = [Path(p) for p in inputs if p is not None]
        self.planned: dict[Path, str] = {}
        self.written: list[Path] = []

    def plan(self, filename: str, what: str = "") -> Path:
        """Reserve `folder/filename`: one safe component, confined, unique, not an input."""
        check_name(filename, key=None)
        path = self.folder / filename
        if path.is_dir() and not path.is_symlink():  # the rename onto it would fail at the end
            raise InputError(f"a folder is where the output {filename!r} goes; move it or "
                             f"choose another {self.option}", path)
        # One safe component cannot leave the folder; a link already there is replaced by
        # the rename (atomic_write), never written through.
        assert Path(os.path.abspath(path)).parent == Path(os.path.abspath(self.folder))
        if path in self.planned:
            raise InputError(f"two outputs are both named {filename!r} ({self.planned[path]} "
                             f"and {what}); give the inputs distinct names")
        for inp in self.inputs:
            if path.resolve() == inp.resolve() or (path.exists() and _same(path, inp)):
                raise InputError(f"the output {path} would overwrite this input of the run; "
                                 f"choose another {self.option} or name", inp)
        self.planned[path] = what or filename
        return path

    def done(self, path) -> None:
        """Record `path` as written (complete)."""
        self.written.append(Path(path))

    def summary(self) -> str:
        """One line: how many files are complete, and where."""
        n = len(self.written)
        return f"{n} file(s) complete in {self.folder}/"
