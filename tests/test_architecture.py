"""The layout's rules, read from the source (ast), not from anyone's memory of it:

- no import cycle between jaxskin's modules (function-level imports count: a lazy import
  is still a dependency);
- the library never imports the application (`jaxskin.cli`, `jaxskin.editor`,
  `jaxskin.cluster`, the console entry points);
- no module imports another module's private name (`from x import _y`, `x._y`), nor a
  private module (`_y.py`) of another package: privacy is per module, and a package's
  private files are its own;
- the module map (`jaxskin/__init__.py`'s docstring) names every module.

Each rule is also tested on a small made-up package, so that a rule that can no longer fail
fails here."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
APP = ("jaxskin.cli", "jaxskin.editor", "jaxskin.cluster", "jaxskin._console",
       "jaxskin.__main__")


def module_files(root: Path = ROOT) -> dict[str, Path]:
    """`{dotted name: file}` for every module of the installed package: `jaxskin/` and the
    repository's `fitting/`, which installs as `jaxskin.fitting`."""
    out = {}
    for base, prefix in ((root / "jaxskin", ["jaxskin"]), (root / "fitting", ["jaxskin", "fitting"])):
        for path in sorted(base.rglob("*.py")):
            parts = prefix + list(path.relative_to(base).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


def _package(name: str, path: Path) -> str:
    return name if path.name == "__init__.py" else name.rpartition(".")[0]


def imports(mods: dict[str, Path]) -> list[tuple[str, str, str | None, int]]:
    """Every import of a jaxskin module, as `(importer, imported module, name or None,
    line)`: `from a import b` where `a.b` is a module is `(…, "a.b", None, …)`, else
    `(…, "a", "b", …)`; `x._y` where `x` is a name bound to a jaxskin module is
    `(…, x's module, "_y", …)`."""
    found = []
    for name, path in mods.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        package = _package(name, path)
        bound: dict[str, str] = {}  # local name → the jaxskin module it is bound to
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - node.level + 1]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                if target.split(".")[0] != "jaxskin":
                    continue
                for alias in node.names:
                    sub = f"{target}.{alias.name}"
                    if sub in mods:
                        found.append((name, sub, None, node.lineno))
                        bound[alias.asname or alias.name] = sub
                    else:
                        found.append((name, target, alias.name, node.lineno))
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name in mods:
                        found.append((name, alias.name, None, node.lineno))
                        if alias.asname:
                            bound[alias.asname] = alias.name
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                    and node.value.id in bound and node.attr.startswith("_")
                    and not node.attr.startswith("__")):
                found.append((name, bound[node.value.id], node.attr, node.lineno))
    return found


def graph(mods, found) -> dict[str, set[str]]:
    edges: dict[str, set[str]] = {m: set() for m in mods}
    for importer, target, _, _ in found:
        if target in mods and target != importer:
            edges[importer].add(target)
    return edges


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out = []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(edges[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def is_app(name: str) -> bool:
    return any(name == a or name.startswith(a + ".") for a in APP)


def library_imports_of_the_app(found) -> list[str]:
    return [f"{a} imports {b} (line {line})" for a, b, _, line in found
            if not is_app(a) and is_app(b)]


def private_crossings(mods, found) -> list[str]:
    """`_name`s taken from another module, and private modules imported from outside
    their package."""
    bad = []
    for importer, target, attr, line in found:
        package = _package(importer, mods[importer])
        if attr is not None and attr.startswith("_") and not attr.startswith("__"):
            sub = f"{target}.{attr}"
            own = sub in mods and sub.rpartition(".")[0] == package
            if not own and target != importer:
                bad.append(f"{importer} (line {line}) takes {attr} from {target}")
        elif attr is None:
            parent, _, last = target.rpartition(".")
            if last.startswith("_") and not last.startswith("__") and parent != package \
                    and not package.startswith(parent + "."):
                bad.append(f"{importer} (line {line}) imports {target}, private to {parent}")
    return bad


@pytest.fixture(scope="module")
def layout():
    mods = module_files()
    return mods, imports(mods)


def test_no_import_cycle(layout):
    mods, found = layout
    assert cycles(graph(mods, found)) == []


def test_the_library_never_imports_the_app(layout):
    _, found = layout
    assert library_imports_of_the_app(found) == []


def test_no_private_name_crosses_a_module(layout):
    mods, found = layout
    assert private_crossings(mods, found) == []


def _public_modules(mods) -> list[str]:
    return [m for m in mods if not any(p.startswith("_") for p in m.split("."))
            and m != "jaxskin"]


def test_the_module_map_names_every_module(layout):
    """Each public module and package, by its name relative to `jaxskin` (`cli`,
    `fitting.image`, `shading.blinn`), in the map of `jaxskin/__init__.py`'s docstring
    (the documentation's API page of `jaxskin` shows it; docs/development.md links there)."""
    import jaxskin

    mods, _ = layout
    named = set(re.findall(r"`([a-z_.]+)`", jaxskin.__doc__))
    missing = [m for m in _public_modules(mods) if m.removeprefix("jaxskin.") not in named]
    assert missing == []
    assert "reference/api/jaxskin.md" in (ROOT / "docs" / "development.md").read_text()


# --- the rules on made-up packages: each must be able to fail ---------------------------------

def _made_up(tmp_path, files: dict[str, str]) -> dict[str, Path]:
    for rel, text in files.items():
        path = tmp_path / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return module_files(tmp_path)


def test_the_rules_fail_where_they_should(tmp_path):
    mods = _made_up(tmp_path, {
        "jaxskin/__init__.py": "",
        "jaxskin/a.py": "from . import b\n",
        "jaxskin/b.py": "def f():\n    from .a import g\n",           # a lazy cycle
        "jaxskin/core.py": "from .cli import main\nfrom .c import _hidden\n",
        "jaxskin/c.py": "from . import km\nx = km._parts\n",
        "jaxskin/km.py": "_parts = 1\n",
        "jaxskin/cli/__init__.py": "from ._main import main\n",
        "jaxskin/cli/_main.py": "from . import _run\nfrom .. import km\n",
        "jaxskin/cli/_run.py": "",
        "jaxskin/editor/__init__.py": "from ..cli import _run\n",
        "fitting/__init__.py": "",
        "fitting/image/__init__.py": "from ._keys import k\n",
        "fitting/image/_keys.py": "from jaxskin.fitting.image import _solve\n",
        "fitting/image/_solve.py": "",
    })
    found = imports(mods)
    assert cycles(graph(mods, found)) == [["jaxskin.a", "jaxskin.b"]]
    assert library_imports_of_the_app(found) == ["jaxskin.core imports jaxskin.cli (line 1)"]
    assert sorted(private_crossings(mods, found)) == [
        "jaxskin.c (line 2) takes _parts from jaxskin.km",
        "jaxskin.core (line 2) takes _hidden from jaxskin.c",
        "jaxskin.editor (line 1) imports jaxskin.cli._run, private to jaxskin.cli",
    ]


def test_every_package_is_in_the_wheel():
    """pyproject lists the packages by name (the repository's fitting/ and data/ install
    under jaxskin): a package missing there is missing from the wheel, though an editable
    install still finds it."""
    import tomllib

    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
                 ["packages"])
    packages = {name for name, path in module_files().items() if path.name == "__init__.py"}
    packages.add("jaxskin.data")
    assert packages == listed
