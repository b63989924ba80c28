"""The README starts with exactly two commands, and CI runs the second one verbatim."""

import importlib.util
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def readme_commands():
    text = (ROOT / "README.md").read_text()
    first_block = re.search(r"```bash\n(.*?)```", text, re.S)
    assert first_block and text.index("```bash") < text.index("\n\n", text.index("# jaxskin")) + 3
    return [line for line in first_block.group(1).splitlines() if line.strip()]


def test_readme_starts_with_two_commands():
    commands = readme_commands()
    assert len(commands) == 2
    install_run, install_test = commands
    assert "pip install -e ." in install_run and "jaxskin render" in install_run
    assert "'.[test]'" in install_test and "pytest" in install_test


def test_ci_runs_the_readme_test_command_verbatim():
    ci = (ROOT / ".ci" / "run").read_text().splitlines()
    assert readme_commands()[1] in ci


def test_readme_main_command_renders_the_default_scene():
    install_run = readme_commands()[0]
    assert "jaxskin render hand" in install_run
    assert (ROOT / "data" / "scenes" / "hand.toml").is_file()


# --- Every Python and shell example in the README runs (issue 13, item 9).

JAXSKIN = Path(sys.executable).parent / "jaxskin"  # the script of the environment under test
SMALL = ["-D", "texture.size=64", "-D", "camera.size=32", "-D", "camera.height=0"]


def fenced(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", (ROOT / "README.md").read_text(), re.S)


def shell_examples() -> list[str]:
    """Every command line of every ```bash block but the first (the install commands: CI
    runs the second verbatim, and the first's render part is kept here)."""
    first, *rest = fenced("bash")
    install_run = first.splitlines()[0]
    render_part = install_run.split("&&")[-1].strip().replace(".venv/bin/jaxskin", "jaxskin")
    return [render_part] + [line for block in rest for line in block.splitlines()
                            if line.strip() and not line.lstrip().startswith("#")]


def test_readme_links_stay_inside_the_repository():
    text = (ROOT / "README.md").read_text()
    assert "../shared" not in text and "JAXSKIN_DATA" not in text
    for target in re.findall(r"\]\(([^)#][^)]*)\)", text):
        assert "://" in target or (ROOT / target).exists(), target


def test_readme_python_examples_run(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    blocks = fenced("python")
    assert len(blocks) >= 2
    for block in blocks:
        exec(compile(block, "README.md", "exec"), {})  # noqa: S102


@pytest.mark.slow
def test_readme_shell_examples_run(tmp_path, capsys, monkeypatch):
    """Each line runs in an empty folder; renders get tiny sizes appended (-D wins in
    order). Files the examples name are made first: the README's scene file as
    my_scene.toml, a Lafortune file at out/skin_fit.json (the fit-brdf example comes later),
    the example measurements at data/measurements/, the BRDF samples at data/brdf/, the skin
    spectra at data/spectra/ (the paths as in a checkout). The benchmark scripts take
    minutes: for those lines the script is imported and must have `main`
    (tests/test_benchmarks_smoke.py runs their parts). `jaxskin list` runs as the
    environment's `jaxskin` script, a process of its own; the other lines call the same
    `main` in this process (a process each cost 1-2 s of start-up and a reload of its
    programs: the command line is the same, and their exit codes and files are checked)."""
    from jaxskin.cli import main
    from jaxskin.formats import write_lafortune
    from jaxskin.shading import lafortune

    if fenced("toml"):
        (tmp_path / "my_scene.toml").write_text(fenced("toml")[0])
    write_lafortune(lafortune.skin(), tmp_path / "out" / "skin_fit.json")
    (tmp_path / "data").mkdir()
    shutil.copytree(ROOT / "data" / "measurements", tmp_path / "data" / "measurements")
    shutil.copytree(ROOT / "data" / "brdf", tmp_path / "data" / "brdf")
    shutil.copytree(ROOT / "data" / "spectra", tmp_path / "data" / "spectra")
    shutil.copytree(ROOT / "data" / "textures", tmp_path / "data" / "textures")
    monkeypatch.chdir(tmp_path)
    ran, processes = 0, 0
    for line in shell_examples():
        words = shlex.split(line, comments=True)
        if words[0] == ".venv/bin/python" and words[1].startswith("benchmarks/"):
            spec = importlib.util.spec_from_file_location("bench", ROOT / words[1])
            sys.path.insert(0, str(ROOT / "benchmarks"))
            try:
                module = importlib.util.module_from_spec(spec)
                spec.loader.exec_module(module)
            finally:
                sys.path.remove(str(ROOT / "benchmarks"))
            assert callable(module.main), line
            continue
        if words[0] == "jaxskin":
            argv = words[1:]
        elif words[:3] == ["python", "-m", "jaxskin"]:
            argv = words[3:]
        else:
            raise AssertionError(f"README command not handled by this test: {line}")
        if "render" in words:
            argv += SMALL
        if argv == ["list"]:  # the script itself, as a shell runs it
            proc = subprocess.run([str(JAXSKIN), *argv], cwd=tmp_path, capture_output=True,
                                  text=True, timeout=300)
            code, out, err = proc.returncode, proc.stdout, proc.stderr
            assert "scene" in out, out
            processes += 1
        else:
            code = main(argv)
            out, err = capsys.readouterr()
        assert code == 0, (line, err)
        for written in re.findall(r"^  (\S+)$", out, re.M):
            assert (tmp_path / written).stat().st_size > 0, (line, written)
        ran += 1
    assert ran >= 5  # the main command's render and the README's four example lines
    assert processes == 1  # `jaxskin list` is in the README: the script ran once
