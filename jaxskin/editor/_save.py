"""The session's files written: Save (a scene and its painted maps) and uploads, kept in
the output folder; a saved scene keeps its source's comments."""

from __future__ import annotations

import os
import tomllib
from pathlib import Path

from .. import cosmetics, maps
from ..io import InputError, atomic_write
from ..outputs import MAX_NAME_BYTES, check_name
from ..scene import (
    BUILTIN_SCENES,
    dumps,
    parse_scene,
    toml_text,
)
from ._document import EditorError, relocate

__all__ = ["Saving", "keep_comments"]


class Saving:
    """The `Session`'s files written (its `save` and `upload`)."""

    def save(self, name: str, overwrite: bool = False) -> list[str]:
        """Write `<output>/<name>.toml` and each painted map as `<name>_<layer>.png` (16-bit
        grey) beside it: a scene `jaxskin render` renders to the image shown. The session
        then edits the saved file."""
        if isinstance(name, str) and name.lower().endswith(".toml"):
            name = name[:-5]  # "my_makeup.toml" writes my_makeup.toml, not .toml.toml
        try:
            check_name(name, "save")
        except InputError as e:
            raise EditorError(e.message, 400, "name") from None
        toml_path = self.output / f"{name}.toml"
        layers = [spec.name for spec in self.scene.layers]
        pngs = {layer: self.output / f"{name}_{layer}.png" for layer in self.paint
                if layer in layers}
        for layer, p in [(None, toml_path), *pngs.items()]:  # all before any is looked at
            _file_name(p.name, layer)
            self.output_file(p.name)
        for p in [toml_path, *pngs.values()]:
            if os.path.lexists(p):
                _replaceable(p, self.output)
            if p.exists() and not overwrite:
                raise EditorError(f"{p.name} exists in {self.output}; save with overwrite to "
                                  "replace it", 409, "name")
            if p.exists() and p.resolve() == self.path.resolve() and self.source in \
                    BUILTIN_SCENES:
                raise EditorError("cannot overwrite a built-in scene", 403, "name")
        doc = self.document()
        doc["name"] = name
        relocate(doc, self.path.parent, self.output)
        for table in doc.get("layer", []):
            if table.get("name") in pngs:
                for k in ("image", "ellipse", "polygon"):
                    table.pop(k, None)
                table["image"] = pngs[table["name"]].name
        text = keep_comments(self.text, doc)
        self.output.mkdir(parents=True, exist_ok=True)
        for layer, p in pngs.items():
            with atomic_write(p, "wb") as fh:
                fh.write(maps.png16_bytes(self.paint[layer]))
            self.written.append(p)
        with atomic_write(toml_path, "w") as fh:
            fh.write(text)
        self.written.append(toml_path)
        paint, version = self.paint, self.version
        self.open(str(toml_path), {})
        self.paint, self.saved_as = paint, str(toml_path)
        self.saved_paint = dict(paint)  # strokes replace arrays: `is` tells what changed
        self.scene = self._build({}, paint)
        self.version = version + 1
        return [str(toml_path), *(str(p) for p in pngs.values())]

    def upload(self, name: str, data: bytes) -> str:
        """Keep a file the page uploads (a scene `.toml`, or a cosmetic material `.json` from
        `jaxskin calibrate`) in the output folder, checked first: the way to bring in a
        file from outside the session's folders. Returns its path."""
        try:
            check_name(name, "upload")
        except InputError as e:
            raise EditorError(e.message, 400, "name") from None
        suffix = Path(name).suffix
        if suffix not in (".toml", ".json"):
            raise EditorError("expected a scene (.toml) or a material (.json)", 400, "name")
        target = self.output_file(name)  # a link that leads outside: 403, nothing read
        if os.path.lexists(target):
            _replaceable(target, self.output)
            # compared only when it is a file of this folder's own (a hard link may be
            # another name of a file outside) and of the same size (a large file there is
            # not read to tell it differs)
            st = target.stat()
            if st.st_nlink == 1 and st.st_size == len(data) and target.read_bytes() == data:
                return str(target)
            other = "with other contents" if st.st_nlink == 1 else "(a file with other names)"
            raise EditorError(f"{name} exists in {self.output} {other}; rename the file to "
                              "upload it", 409, "name")
        import tempfile

        with tempfile.TemporaryDirectory() as tmp:
            probe = Path(tmp) / name
            probe.write_bytes(data)
            try:
                if suffix == ".json":
                    cosmetics.check_material(probe)
                else:
                    doc = tomllib.loads(toml_text(data, name))
                    scene = parse_scene(doc, target, allow=lambda k, f: self._allow(k, f, name))
                    check_name(scene.name, target)  # as render checks it: a
                    # name = "../../x" is refused here, not only by a later render
            except InputError as e:
                raise EditorError(f"{name}: {e.message}", 400, e.key) from None
            except (UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
                raise EditorError(f"{name}: not a TOML scene ({e})", 400) from None
        self.output.mkdir(parents=True, exist_ok=True)
        with atomic_write(target, "wb") as fh:
            fh.write(data)
        self.written.append(target)
        return str(target)


def _file_name(name: str, layer: str | None) -> None:
    """An `EditorError` (400) when a file Save writes, `<name>.toml` or a painted layer's
    `<name>_<layer>.png`, is longer than a file name may be (`outputs.MAX_NAME_BYTES`: a
    save name near its limit with a long layer name was an OSError, a 500). The save name
    itself is checked as every output name is; the layer's is letters, digits and _."""
    size = len(name.encode("utf-8", "surrogatepass"))
    if size > MAX_NAME_BYTES:
        what = f"layer {layer!r}'s painted map" if layer else "the scene"
        raise EditorError(f"{what} would be saved as {name[:40]!r}... ({size} bytes in "
                          f"UTF-8), longer than a file name may be here ({MAX_NAME_BYTES} "
                          f"bytes): save under a shorter name"
                          f"{' or rename the layer' if layer else ''}", 400, "name")


def _replaceable(path: Path, output: Path) -> None:
    """An `EditorError` (409) when `path`, which exists, is no regular file that a save or
    an upload may compare or replace: a folder (replaced, a 500), a named pipe (read,
    the editor hung), a link loop."""
    if not path.is_file():
        raise EditorError(f"{path.name} in {output} is not a regular file (a folder, a "
                          "pipe or a broken link?); choose another name", 409, "name")


def keep_comments(source: str, doc: dict) -> str:
    """`doc` as TOML text, written over the `source` text it was edited from so that the
    source's comments and layout stay where its keys stay (tomlkit, the `edit` extra):
    changed values are replaced, new keys added at the end of their table, removed ones
    dropped. The result must read back equal to `doc`, as `dumps(doc)` does; when it does
    not (or tomlkit is missing) it is `dumps(doc)`, with no comments."""
    plain = dumps(doc)
    try:
        import tomlkit

        styled = tomlkit.parse(source)
        _sync(styled, doc)
        text = tomlkit.dumps(styled)
        if tomllib.loads(text) == tomllib.loads(plain):
            return text
    except Exception:  # any surprise in the styled route: the plain text is always right
        pass
    return plain


def _match_tables(have, value: list) -> None:
    def plain(h):
        return h.unwrap() if hasattr(h, "unwrap") else h

    free = list(range(len(have)))
    match: list = [None] * len(value)
    tests = [lambda h, v: plain(h) == v,
             lambda h, v: "name" in v and plain(h).get("name") == v["name"]]
    for same in tests:
        for i, v in enumerate(value):
            j = next((j for j in free if match[i] is None and same(have[j], v)), None)
            if j is not None:
                match[i] = j
                free.remove(j)
    if len(have) == len(value):
        for i in range(len(value)):
            if match[i] is None and i in free:
                match[i] = i
                free.remove(i)
    kept = list(have.body) if hasattr(have, "body") else list(have)
    while len(have):  # emptied and refilled in place: the array's layout stays
        del have[-1]
    for i, v in enumerate(value):
        if match[i] is None:
            have.append(v)
        else:
            _sync(kept[match[i]], v)
            have.append(kept[match[i]])


def _sync(table, want: dict) -> None:
    """Make the tomlkit `table` equal to `want` in place, touching only what differs."""
    for key in [k for k in table if k not in want]:
        del table[key]
    for key, value in want.items():
        have = table.get(key)
        if isinstance(value, dict) and isinstance(have, dict):
            _sync(have, value)
        elif (isinstance(value, list) and value and all(isinstance(v, dict) for v in value)
              and isinstance(have, list) and have and all(isinstance(h, dict) for h in have)):
            # an array of tables (field edits, layers): each wanted table is matched to a
            # source table, which keeps its comments, by equal content, then by equal
            # `name` (layers), then by position when no table was added or removed;
            # unmatched ones are new, without comments (a deleted edit's comment must not
            # move onto the next one)
            _match_tables(have, value)
        elif have is None or have != value or type(have.unwrap() if hasattr(have, "unwrap")
                                                 else have) is not type(value):
            table[key] = value
