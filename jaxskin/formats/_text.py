"""Reading text files: the bytes of a table or a document as text (UTF-8, UTF-16 with or
without a byte-order mark, a fallback such as Windows-1252), and a text table's rows."""

from __future__ import annotations

import codecs
import contextlib
import csv
from pathlib import Path

from ..io import InputError, check_regular

DELIMITERS = (",", "\t", ";")
MAX_BYTES = 256 * 2**20  # a spectrum at 0.01 nm with 50 columns is ~40 MB

# Files a table reader is given by mistake, by their first bytes: named in the error
# (not just "a binary file (a NUL byte)" with the line of that byte).
BINARY_KINDS = ((b"\x89PNG\r\n\x1a\n", "a PNG image"), (b"\xff\xd8\xff", "a JPEG image"),
                (b"II*\0", "a TIFF image"), (b"MM\0*", "a TIFF image"),
                (b"GIF8", "a GIF image"), (b"%PDF", "a PDF document"),
                (b"PK\x03\x04", "a ZIP archive (an Excel .xlsx workbook?)"),
                (b"\xd0\xcf\x11\xe0", "an Office document (an Excel .xls workbook?)"))


def read_text(path, fallback: str | None = None, expected: str = "a CSV table (export it "
              "as CSV)") -> str:
    """A text file's contents (UTF-8, or UTF-16 when it starts with UTF-16's byte-order mark;
    the mark dropped); `InputError` if it is not one: missing, unreadable, binary, not UTF-8
    (unless it decodes as the `fallback` encoding, e.g. "cp1252" for Windows exports such as
    the NIST file) or larger than `MAX_BYTES`. A file that starts like an image, a PDF or a
    workbook is named as one (`BINARY_KINDS`), with `expected` saying what was wanted."""
    path = Path(path)
    try:
        check_regular(path, expected)
        size = path.stat().st_size
        if size > MAX_BYTES:
            raise InputError(f"{size / 2**20:.0f} MiB is larger than the {MAX_BYTES >> 20} MiB "
                             "a table may be", path)
        with open(path, "rb") as f:  # bounded: a regular file in /proc says size 0 and
            raw = f.read(MAX_BYTES + 1)  # may grow while read
        if len(raw) > MAX_BYTES:
            raise InputError(f"larger than the {MAX_BYTES >> 20} MiB a table may be", path)
    except FileNotFoundError:
        raise InputError("no such file", path) from None
    except IsADirectoryError:
        raise InputError("is a folder, expected a file", path) from None
    except OSError as e:
        raise InputError(f"cannot read ({e.strerror or e.__class__.__name__})", path) from None
    if raw.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        try:
            text = raw.decode("utf-16")  # the mark says which byte order
        except UnicodeDecodeError as e:
            raise InputError(f"not UTF-16 text, though it starts with UTF-16's byte-order mark "
                             f"({e.reason} at byte {e.start})", path) from None
        if "\0" in text:
            raise InputError("a binary file (a NUL character), expected text", path,
                             text[:text.index("\0")].count("\n") + 1)
        return text
    kind = next((k for sig, k in BINARY_KINDS if raw.startswith(sig)), None)
    if kind is not None:  # a file of a kind users pick by mistake: say which
        raise InputError(f"{kind}, not text: expected {expected}", path)
    if b"\0" in raw:
        text = _utf16_without_mark(raw)
        if text is not None:  # Windows "Unicode" saved without the mark
            return text
        line = raw[:raw.index(b"\0")].count(b"\n") + 1
        raise InputError("a binary file (a NUL byte), expected UTF-8 text", path, line)
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        if fallback is not None:
            with contextlib.suppress(UnicodeDecodeError):
                return raw.decode(fallback)
        line = raw[:e.start].count(b"\n") + 1
        nor = "" if fallback is None else f" nor {fallback}"
        raise InputError(f"not UTF-8{nor} text (byte 0x{raw[e.start]:02x})", path,
                         line) from None


def _utf16_without_mark(raw: bytes) -> str | None:
    """`raw` decoded as UTF-16 when it has no byte-order mark but is plainly UTF-16 text:
    an even length, every other byte NUL in its first 2 KiB (Latin text: the high bytes)
    and none of the others, and it decodes with no NUL character; else None."""
    head = raw[:2048]
    if len(raw) % 2 or len(head) < 4:
        return None
    for order, zeros, rest in (("utf-16-le", head[1::2], head[0::2]),
                               ("utf-16-be", head[0::2], head[1::2])):
        if zeros.count(0) >= 0.9 * len(zeros) and rest.count(0) == 0:
            try:
                text = raw.decode(order)
            except UnicodeDecodeError:
                return None
            return None if "\0" in text else text
    return None


def split_row(line: str, delimiter: str) -> list[str]:
    """A row's cells split at `delimiter` (quotes honoured, each cell stripped), without
    trailing empty cells. Raises `csv.Error`."""
    cells = next(csv.reader([line], delimiter=delimiter, skipinitialspace=True), [])
    cells = [c.strip() for c in cells]
    while len(cells) > 1 and cells[-1] == "":
        cells.pop()
    return cells


def text_rows(path):
    """`(line number, cells)` of each row of a text table that is not blank or a comment,
    split at whichever delimiter gives the most cells; nothing for a file that cannot be
    read as text, and no more rows from the first that is not CSV. For messages that
    guess what a file that failed to read was meant to be."""
    try:
        lines = read_text(path, fallback="cp1252").splitlines()
    except InputError:
        return
    for number, raw in enumerate(lines, start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        try:
            yield number, max((split_row(line, d) for d in DELIMITERS), key=len)
        except csv.Error:
            return
