"""The README opens with the two commands a new user copies; CI must run the second verbatim."""

from __future__ import annotations

import re

from conftest import REPO


def _readme_commands() -> list[str]:
    text = (REPO / "README.md").read_text()
    blocks = re.findall(r"```(?:sh|bash|console)?\n(.*?)```", text, flags=re.S)
    return [b.strip() for b in blocks[:2]]


def test_readme_opens_with_two_commands():
    run_cmd, test_cmd = _readme_commands()
    assert "hil run" in run_cmd
    assert "pytest" in test_cmd
    for cmd in (run_cmd, test_cmd):
        assert len(cmd.splitlines()) == 1, "each command is one copy-paste line"
        assert cmd.startswith("python3 -m venv .venv && "), "works on a machine with only Python and pip"


def test_ci_runs_the_readme_test_command_verbatim():
    _, test_cmd = _readme_commands()
    ci = (REPO / ".ci" / "run").read_text().splitlines()
    assert test_cmd in ci
