"""The reference pages, generated from the code: the API pages (one per public module of
`jaxskin` and `jaxskin.fitting`), the scene format from `jaxskin.scene.SCHEMA` and
`LAYER_SCHEMA` (descriptions from the commented TOML example in `jaxskin/scene/__init__.py`'s
docstring), the command line from `jaxskin.cli.parser()`. Each function returns Markdown
and the problems it found (a public name without a docstring, a scene key without a
description); `docs/gen_ref.py` writes the pages at build time and turns each problem into
a warning, which fails `mkdocs build --strict`; `tests/test_docs.py` checks the problems
directly too, without building."""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import re
from pathlib import Path

import griffe
from griffe_fitting import MountFitting

ROOT = Path(__file__).resolve().parents[2]


# --- The API: one page per module -------------------------------------------------------------

def modules() -> list[str]:
    """Every public module and package under jaxskin (fitting included), `__main__` left out."""
    import jaxskin
    import jaxskin.fitting

    names = ["jaxskin"]
    for pkg in (jaxskin, jaxskin.fitting):
        for m in pkgutil.walk_packages(pkg.__path__, prefix=pkg.__name__ + "."):
            parts = m.name.split(".")
            if any(p.startswith("_") for p in parts) or m.name in names:
                continue
            names.append(m.name)
    return names


def summary(doc: str | None) -> str:
    """The first sentence of a docstring, on one line."""
    first = (doc or "").strip().split("\n\n")[0]
    return " ".join(first.split())


def api_pages() -> tuple[dict[str, str], list]:
    """`({path: Markdown}, the API section of the navigation)`."""
    pages: dict[str, str] = {}
    nav = []
    rows = []
    for name in modules():
        module = importlib.import_module(name)
        is_package = hasattr(module, "__path__")
        path = f"reference/api/{name}.md"
        subs = [m for m in modules() if m.rsplit(".", 1)[0] == name] if is_package else []
        # A package of public modules is a page of links; a package of private files (its
        # names re-exported, as `jaxskin.scene`) is documented like a module.
        options = "    options:\n      members: false\n" if subs else ""
        text = f"::: {name}\n{options}"
        if subs:
            text += "\n**Modules:**\n\n" + "".join(
                f"- [`{m}`]({m}.md): {summary(importlib.import_module(m).__doc__)}\n"
                for m in subs)
        pages[path] = text
        nav.append({name: path})
        rows.append(f"| [`{name}`]({name}.md) | {summary(module.__doc__)} |")
    pages["reference/api/index.md"] = (
                "# API\n\nEvery public module of `jaxskin` and `jaxskin.fitting`, each page "
                "generated from the docstrings (Markdown, with **Arguments** / **Returns**; "
                "array shapes as jaxtyping annotations such as `Float[Array, \"*shape n\"]`).\n"
                "Everything numeric follows the dtype of its inputs and is jit-, vmap- and "
                "grad-safe unless its docstring says otherwise.\n\n"
                "| module | what it holds |\n|---|---|\n" + "\n".join(rows) + "\n")
    return pages, [{"API": ["reference/api/index.md", *nav]}]


def missing_docstrings(package: str = "jaxskin", search_paths=(ROOT,)) -> list[str]:
    """Each public module, function, class, method or property (of a public class) of
    `package` without a docstring, as griffe (what mkdocstrings renders from) sees the source."""
    loader = griffe.GriffeLoader(extensions=griffe.load_extensions(MountFitting()),
                                 search_paths=[str(p) for p in search_paths])
    root = loader.load(package)
    loader.resolve_aliases(implicit=False, external=False)
    missing = [] if root.docstring else [root.path]

    def visit(obj):
        for member in obj.members.values():
            if member.is_alias:
                continue
            private_file = member.is_module and not member.name.startswith("__")
            if member.name.startswith("_") and not private_file:
                continue
            if member.is_module:
                if member.name != "__main__":
                    if not member.docstring:
                        missing.append(member.path)
                    visit(member)
                continue
            if not member.is_public:
                continue
            if member.is_function or member.is_class or (
                    member.is_attribute and "property" in member.labels):
                if not member.docstring:
                    missing.append(member.path)
                if member.is_class:
                    visit(member)

    visit(root)
    return missing


# --- The scene format, from the schema --------------------------------------------------------

def toml_descriptions(doc: str) -> dict[str, str]:
    """`{dotted key: comment}` from the commented TOML examples in a docstring. A comment
    starting with more than one space continues the previous one; a table header's comment
    describes the table (`fields.edit`, `layer`, `layer.ellipse`). A key commented out
    (`# vertex = 123  # ...`: an alternative to the key above it, which a valid example
    cannot also give) is described as if it were not."""
    out: dict[str, str] = {}
    last = None
    prefix = ""
    for block in re.findall(r"```toml\n(.*?)```", doc, re.S):
        for line in block.splitlines():
            code, _, comment = line.partition("#")
            if not code.strip() and re.match(r" \w+\s*=[^#]*#", comment):
                code, _, comment = comment.partition("#")
            code = code.strip()
            header = re.fullmatch(r"\[\[?([\w.]+)\]\]?", code)
            key = re.match(r"([\w]+)\s*=", code)
            if header:
                prefix = header.group(1) + "."
                name = header.group(1)
            elif key:
                name = prefix + key.group(1) if prefix else key.group(1)
            else:
                name = None
            continues = comment.startswith("  ")
            text = " ".join(comment.split())
            if text and (continues or name is None) and last is not None:
                out[last] = f"{out[last]} {text}".strip()
            elif name is not None:
                out.setdefault(name, text)
                last = name if text else last
            if name is not None and continues:
                out.setdefault(name, "")
    return out


def prose(text: str) -> str:
    """Plain text (a help string, a comment) made safe in Markdown: `<name>` is not a tag,
    `*` not emphasis, `|` not a table column."""
    return (text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
            .replace("*", "\\*").replace("|", "\\|"))


def fmt(value) -> str:
    if isinstance(value, bool):
        return "`true`" if value else "`false`"
    if isinstance(value, str):
        return f'`"{value}"`'
    if isinstance(value, tuple):
        return "`[" + ", ".join(map(str, value)) + "]`"
    return "—" if value is None else f"`{value}`"


def key_type(kind) -> str:
    return {"vec2": "2 numbers", "vec3": "3 numbers", bool: "boolean", int: "integer",
            float: "number", str: "string"}[kind]


def key_range(spec) -> str:
    if spec.choices is not None:
        return " \\| ".join(fmt(c) for c in spec.choices)
    if spec.lo is not None:
        return f"{number(spec.lo)} – {number(spec.hi)}"
    return ""


def number(x) -> str:
    return str(int(x)) if float(x).is_integer() and abs(x) < 1e12 else f"{x:g}"


def values(spec) -> str:
    """The key's type, and its range or choices."""
    span = key_range(spec)
    if spec.kind == "vec2" and span:
        span = f"each {span}"
    return f"{key_type(spec.kind)}, {span}" if span and spec.choices is None else (
        span or key_type(spec.kind))


def scene_page() -> tuple[str, list[str]]:
    """`(Markdown, the keys without a description)`."""
    from jaxskin import scene

    described = toml_descriptions(scene.__doc__)
    undescribed: list[str] = []
    model_of: dict[str, str] = {}  # a parameter only some material models use: which
    for m, keys in scene.MODEL_PARAMS.items():
        for k in sorted(keys):
            model_of[k] = f"{model_of[k]}, {m}" if k in model_of else m
    # the spectral models' skin is one of two (Scene.skin_model), each with its own keys
    for k in [*scene.BIOPHYSICAL_KEYS.values(), "skin.brightness"]:
        model_of[k] = "the biophysical skin: biophysical, or spectral with skin.model biophysical"
    model_of["skin.melanin"] = "the measured skin: spectral with skin.model nist"

    def describe(key: str) -> str:
        text = described.get(key, "")
        if not text and key not in undescribed:
            undescribed.append(key)
        return prose(text)

    lines = [
        "# Scene files",
        "",
        "A scene is a TOML file (or a built-in name: "
        + ", ".join(f"`{n}`" for n in scene.BUILTIN_SCENES)
        + ", in `data/scenes/`). Every key below may be left out (its default applies), set in "
        "the file, or overridden on the command line with `-D key=value` (e.g. "
        "`-D material.melanin=0.4`, `-D layer.blush.thickness_mm=0.02`) or in Python with "
        "`load_scene(name, [\"key=value\", ...])`, with the same checks: an unknown key is an "
        "error that suggests the nearest valid key, an out-of-range value one that gives the "
        "range.",
        "",
        "**Differentiable** keys become arrays in `Scene.params`: `jax.grad`, `--sweep` and "
        "`jaxskin fit-...` work on them, and changing one does not recompile. **Static** keys "
        "make up `Scene.config`, the jit cache key: they choose which stages run and the "
        "shapes. A scene gets only the parameters its material model uses (named in brackets); "
        "see [What a scene does not need](../explanations/traced.md).",
        "",
        "This page is generated from `jaxskin.scene.SCHEMA` and `LAYER_SCHEMA` (`python "
        "docs/_ext/reference.py` rewrites it; the suite fails when it is stale); the "
        "descriptions are the comments of the example in `jaxskin/scene/__init__.py`.",
        "",
        "## Keys",
        "",
        "| key | default | values | kind | description |",
        "|---|---|---|---|---|",
    ]
    for key, spec in scene.SCHEMA.items():
        kind = "**differentiable**" if spec.param else "static"
        if key in model_of:
            kind += f" ({model_of[key]})"
        lines.append(f"| `{key}` | {fmt(spec.default)} | {values(spec)} | {kind} | "
                     f"{describe(key)} |")
    lines += [
        "",
        "## `[[layer]]`: cosmetic layers",
        "",
        f"{describe('layer')}. Only with the cosmetics model (`material.model` "
        + " or ".join(f'`"{m}"`' for m in getattr(scene, "SPECTRAL_MODELS", ("spectral",)))
        + "). Each layer's values are addressed as `layer.<name>.<key>`; with `-D`, its "
        "numbers and its `material` (`-D layer.blush.material=foundation_dark`, or a JSON "
        "file from `jaxskin calibrate`, taken from the working directory); its image and "
        "regions only in the file.",
        "",
        "| key | default | values | kind | description |",
        "|---|---|---|---|---|",
    ]
    for key, spec in scene.LAYER_SCHEMA.items():
        kind = "**differentiable**" if spec.param else "static"
        lines.append(f"| `{key}` | {fmt(spec.default)} | {values(spec)} | {kind} | "
                     f"{describe('layer.' + key)} |")
    for key in sorted(scene.LAYER_KEYS - set(scene.LAYER_SCHEMA)):
        lines.append(f"| `{key}` | | | static | {describe('layer.' + key)} |")
    for table, keys in (("layer.ellipse", scene.ELLIPSE_KEYS),
                        ("layer.polygon", scene.POLYGON_KEYS),
                        ("fields.edit", scene.EDIT_KEYS)):
        lines += ["", f"## `[[{table}]]`", "", describe(table), "",
                  "| key | description |", "|---|---|"]
        lines += [f"| `{k}` | {describe(f'{table}.{k}')} |" for k in sorted(keys)]
    lines += ["", "## Built-in names", "",
              "What a scene can name without a path (`jaxskin list` prints the same):", "",
              "```text", builtin_names().rstrip(), "```"]
    lines += ["", "## The examples this page reads", "",
              "The commented TOML in `jaxskin/scene/__init__.py`'s docstring, as it stands:", ""]
    for block in re.findall(r"```toml\n(.*?)```", scene.__doc__, re.S):
        lines += ["```toml", block.rstrip(), "```", ""]
    return "\n".join(lines) + "\n", undescribed


def builtin_names() -> str:
    """What `jaxskin list` prints: the built-in scenes, meshes, materials, BRDF presets,
    illuminants and spectral steps."""
    import contextlib
    import io

    from jaxskin.cli import COMMANDS, Run

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        COMMANDS["list"].run(None, Run())
    return out.getvalue()


# --- The command line, from argparse ----------------------------------------------------------

def cli_page() -> str:
    from jaxskin import cli

    parser = cli.parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    helps = {c.dest: c.help for c in sub._choices_actions}

    def section(p: argparse.ArgumentParser, title: str, level: str) -> list[str]:
        formatter = p._get_formatter()
        out = [f"{level} {title}", ""]
        if title in helps:
            out += [f"*{prose(helps[title])}*", ""]
        if p.description:
            out += [prose(p.description), ""]
        out += ["```text", p.format_usage().strip(), "```", "",
                "| argument | notes | description |", "|---|---|---|"]
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                continue
            names = ", ".join(f"`{s}`" for s in a.option_strings) or f"`{a.metavar or a.dest}`"
            if a.option_strings and a.nargs != 0:
                names += f" `{a.metavar or a.dest.upper()}`"
            extra = []
            if a.required and a.option_strings:
                extra.append("required")
            if a.choices:
                extra.append("one of " + ", ".join(f"`{c}`" for c in a.choices))
            if a.default not in (None, False, [], argparse.SUPPRESS):
                extra.append(f"default `{a.default}`")
            if a.nargs == "+":
                extra.append("one or more")
            text = formatter._expand_help(a) if a.help else ""
            out.append(f"| {names} | {'; '.join(extra)} | {prose(' '.join(text.split()))} |")
        out.append("")
        if p.epilog:
            out += [prose(p.epilog), ""]
        return out

    lines = ["# Command line", "",
             "Generated from `jaxskin.cli.parser()`, the parser the `jaxskin` command uses "
             "(`python docs/_ext/reference.py` rewrites this page; the suite fails when it "
             "is stale). "
             "`jaxskin COMMAND --help` prints the same text. "
             "`python -m jaxskin` is the same command line. How outputs are named and the exit "
             "codes: [Outputs and exit codes](outputs.md).", ""]
    lines += section(parser, "jaxskin", "##")
    for name, p in sub.choices.items():
        lines += section(p, name, "##")
    return "\n".join(lines) + "\n"




# The pages kept in the repository as well (so that links to them work where the Markdown is
# read without building the site); tests/test_docs.py fails when they are stale.
KEPT = {"reference/scene.md": lambda: scene_page()[0], "reference/cli.md": cli_page}


if __name__ == "__main__":  # python docs/_ext/reference.py: rewrite the kept pages
    for name, page in KEPT.items():
        (ROOT / "docs" / name).write_text(page())
        print(f"wrote docs/{name}")
