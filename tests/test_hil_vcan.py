"""`hil vcan -- COMMAND`: a command run where vcan0 exists (native, else User-Mode Linux)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from hil import uml

REPO = Path(__file__).resolve().parent.parent
HIL = [sys.executable, "-m", "hil"]

# Inside: a frame sent on vcan0 by one socket arrives at another; progress on stderr; exit code 3.
PROBE = r"""
import can, json, sys
a = can.Bus(interface="socketcan", channel="vcan0")
b = can.Bus(interface="socketcan", channel="vcan0")
print("probe: buses open", file=sys.stderr, flush=True)
a.send(can.Message(arbitration_id=0x123ABC, data=b"\x01\x02", is_extended_id=True))
m = b.recv(5.0)
print(json.dumps({"id": m.arbitration_id, "data": list(m.data)}))
a.shutdown(); b.shutdown()
sys.exit(3)
"""


def _hil(*args, timeout=120):
    return subprocess.run([*HIL, *args], capture_output=True, text=True, timeout=timeout, cwd=REPO)


def test_usage_errors_are_one_line():
    for argv, text in ((["vcan"], "no command given"), (["vcan", "--", "no-such-command-xyz"], "command not found"),
                       (["vcan", "--timeout", "0", "--", "true"], "--timeout must be > 0")):
        r = _hil(*argv)
        assert r.returncode == 2 and text in r.stderr and "Traceback" not in r.stderr
        assert len(r.stderr.strip().splitlines()) == 1


def test_command_runs_on_a_real_vcan0_with_its_output_and_exit_code():
    try:
        kind, why = uml.detect("vcan0")
    except uml.VcanUnavailable as exc:
        print(f"\nhil vcan test skipped: {exc}")
        pytest.skip(str(exc))
    print(f"\nhil vcan: {why}")
    r = _hil("vcan", "--", sys.executable, "-c", PROBE, timeout=180)
    assert r.returncode == 3, r.stderr[-2000:]
    assert json.loads(r.stdout.strip().splitlines()[-1]) == {"id": 0x123ABC, "data": [1, 2]}
    assert "probe: buses open" in r.stderr
    assert ("User-Mode Linux" in r.stderr) == (kind == "uml")
