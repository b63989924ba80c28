"""The command line: help for every option, version, the persistent compilation cache."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from jaxskin import __version__
from jaxskin.cli import main

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "data" / "measurements" / "blush_rose.csv"


def test_help_explains_every_option(capsys):
    with pytest.raises(SystemExit) as info:
        main(["calibrate", "--help"])
    assert info.value.code == 0
    text = capsys.readouterr().out
    for option in ("--output", "--thickness", "--percent", "--smooth", "--noise", "--no-report"):
        assert option in text
    with pytest.raises(SystemExit) as info:
        main(["fit-brdf", "--help"])
    assert info.value.code == 0
    text = capsys.readouterr().out
    for option in ("--output", "--lobes", "--starts", "--seed", "--no-report"):
        assert option in text
    assert main([]) == 0
    text = capsys.readouterr().out
    assert "calibrate" in text and "fit-brdf" in text


def test_version(capsys):
    with pytest.raises(SystemExit):
        main(["--version"])
    assert capsys.readouterr().out.strip() == f"jaxskin {__version__}"


def test_unknown_option_is_a_usage_error():
    proc = subprocess.run(
        [sys.executable, "-m", "jaxskin.cli", "calibrate", str(EXAMPLE), "-o", "x", "--smoth", "1"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2 and "--smoth" in proc.stderr


@pytest.mark.parametrize("off", [False, True])
def test_persistent_compilation_cache(tmp_path, off):
    cache = tmp_path / "cache"
    env = {**os.environ, "JAXSKIN_CACHE_DIR": str(cache)}
    if off:
        env["JAXSKIN_NO_COMPILE_CACHE"] = "1"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "jaxskin.cli",
            "calibrate",
            str(EXAMPLE),
            "-o",
            str(tmp_path / "out"),
            "--no-report",
        ],
        capture_output=True,
        text=True,
        env=env,
    )
    assert proc.returncode == 0, proc.stderr
    entries = list(cache.rglob("*")) if cache.exists() else []
    assert (len(entries) == 0) if off else (len(entries) > 0)
