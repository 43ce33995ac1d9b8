"""Every start-up failure names its cause on the console with exit 2 (issue 16): a busy ground-station
port, SocketCAN or vcan0 missing (with the `hil vcan` hint), an in-process-only CAN interface."""

from __future__ import annotations

import os
import socket

import pytest

from hil import cli


def _has_vcan0() -> bool:
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
    except (OSError, AttributeError):
        return False
    return os.path.exists("/sys/class/net/vcan0")


def _fails_with(argv, capsys) -> str:
    rc = cli.main(argv)
    err = capsys.readouterr().err
    assert rc == 2, err
    assert "Traceback" not in err
    return err.strip().splitlines()[-1]


@pytest.mark.parametrize("command", ["run", "sim", "autopilot", "soak"])
def test_virtual_can_is_refused_with_the_reason(command, capsys, tmp_path):
    argv = [command, "--actuators", "can", "--can-interface", "virtual"]
    if command == "run":
        argv += ["--out", str(tmp_path)]
    last = _fails_with(argv, capsys)
    assert "exists only inside one process" in last and "vcan0" in last


@pytest.mark.skipif(_has_vcan0(), reason="this machine has SocketCAN and vcan0: nothing missing to report")
@pytest.mark.parametrize("command", ["run", "autopilot"])
def test_missing_vcan_names_hil_vcan(command, capsys, tmp_path):
    argv = [command, "--actuators", "can"]
    if command == "run":
        argv += ["--out", str(tmp_path)]
    last = _fails_with(argv, capsys)
    assert "hil vcan" in last and "Errno 97" not in last.split("(")[0]


def test_a_missing_can_channel_is_named(capsys, monkeypatch):
    # Whatever this kernel has, a channel that does not exist is reported by name.
    last = _fails_with(["sim", "--actuators", "can", "--can-channel", "vcan-does-not-exist"], capsys)
    assert "hil vcan" in last and ("vcan-does-not-exist" in last or "no SocketCAN" in last)


def test_gcs_port_in_use_is_named_by_hil_run(capsys, tmp_path):
    busy = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    busy.bind(("127.0.0.1", 0))
    port = busy.getsockname()[1]
    try:
        last = _fails_with(["run", "--gcs", f"udpin:127.0.0.1:{port}", "--out", str(tmp_path / "r"),
                            "--duration", "5", "--no-plot"], capsys)
    finally:
        busy.close()
    assert f"cannot bind UDP 127.0.0.1:{port}" in last and "in use" in last, last


def test_gcs_tcp_port_in_use_is_named_by_hil_autopilot(capsys):
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen(1)
    port = busy.getsockname()[1]
    try:
        last = _fails_with(["autopilot", "--gcs", f"tcpin:127.0.0.1:{port}"], capsys)
    finally:
        busy.close()
    assert f"cannot listen on TCP 127.0.0.1:{port}" in last and "in use" in last, last
