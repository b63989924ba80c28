"""The README starts with exactly two commands, and CI runs the second one verbatim."""

import re
from pathlib import Path

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
