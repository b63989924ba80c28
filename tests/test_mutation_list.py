"""benchmarks/mutation.py runs on demand, not here (minutes); here only its list is checked:
at least 30 mutants, each pattern occurs exactly once in the library as it is, each changes
something, each names test files that exist. A refactor that moves a pattern fails here,
so the list is updated with it."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
import mutation  # noqa: E402


def test_every_mutant_applies_exactly_once():
    assert len(mutation.MUTANTS) >= 30
    assert mutation.check() == []
