"""The Python examples in the docs run as written (issue 32 point 5: the docs' examples cannot rot).

Every ```python block of the docs listed in RUNNABLE is executed, in order, from the repository root
(the examples' relative paths are the repository's); the blocks of docs/gcs.md need a live boat and a
MAVSDK ground station and are run by tests/test_gcs_mavsdk*.py in their own form instead."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
RUNNABLE = ("docs/planner.md",)
BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


def python_blocks(doc: str) -> list[str]:
    """The ```python blocks of ``doc`` (a path relative to the repository), in order."""
    return BLOCK.findall((REPO / doc).read_text())


def test_every_doc_with_python_examples_is_run_or_said_not_to_be():
    docs = {str(p.relative_to(REPO)) for p in [*(REPO / "docs").glob("*.md"), REPO / "README.md"]
            if "```python" in p.read_text()}
    assert docs <= set(RUNNABLE) | {"docs/gcs.md"}, docs - set(RUNNABLE)


@pytest.mark.parametrize("doc", RUNNABLE)
def test_the_python_examples_run(doc, monkeypatch):
    blocks = python_blocks(doc)
    assert blocks, f"{doc} has no ```python block"
    monkeypatch.chdir(REPO)
    for code in blocks:
        ns: dict[str, object] = {"__name__": "__doc_example__"}
        exec(compile(code, doc, "exec"), ns)  # noqa: S102 - the docs' own code
        if doc == "docs/planner.md":
            # The planner API example (bench_maze, inflate(1.5)) finds a path: it once reported
            # "different free regions" (issue 32 point 5).
            result = ns["result"]
            assert result.status == "exact", result  # type: ignore[attr-defined]
            assert len(result.path) >= 2 and result.cost > 0  # type: ignore[attr-defined]
