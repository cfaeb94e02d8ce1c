"""The output bytes of a fixed matrix of jobs stay what they were (tests/golden_cases.py)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
import golden_cases

RECORDED: dict[str, str] = json.loads(golden_cases.GOLDEN.read_text())
CASES = golden_cases.cases()


def test_matrix_is_recorded_whole() -> None:
    assert sorted(RECORDED) == sorted(CASES)


@pytest.mark.parametrize("name", sorted(CASES))
def test_output_bytes_are_golden(name: str) -> None:
    assert golden_cases._digest(CASES[name]()) == RECORDED[name], (
        f"{name}: the output changed; if that is meant, record the matrix again "
        "(tests/golden_cases.py --record) in a commit that says why"
    )
