"""Checks run on a real vcan0 (natively or inside User-Mode Linux) by tests/test_can_vcan.py.

Two processes' worth of sockets in one: the ESC nodes and an intruder on socketcan vcan0. Prints
one JSON line: what the ESC nodes applied and rejected.
"""

from __future__ import annotations

import json
import socket

import can

from common import dronecan_codec as dc
from common.can_params import open_bus
from hil import settings
from simulator.esc import EscBank
from simulator.vessel import Vessel


def main() -> None:
    cfg = settings.load()
    esc = EscBank(open_bus(cfg.can), cfg.can, cfg.esc, Vessel(cfg.vessel))
    tx = can.Bus(interface="socketcan", channel=cfg.can.channel)
    good = dc.to_frames(dc.RAW_COMMAND, dc.raw_command([1000, -1000]), cfg.can.autopilot_node_id, 0)
    frames = good + [
        can.Message(arbitration_id=good[0].arbitration_id, data=b"", is_extended_id=True),       # no tail byte
        *dc.to_frames(dc.RAW_COMMAND, dc.serialize(dc.make(dc.RAW_COMMAND, cmd=[-8192, 5])),
                      cfg.can.autopilot_node_id, 1),
        *dc.to_frames(dc.RAW_COMMAND, dc.raw_command([7, 7]), 99, 0),                              # unknown node
        can.Message(arbitration_id=0x123, data=b"\x01\xc0", is_extended_id=False),               # 11-bit frame
    ]
    for f in frames:
        tx.send(f)
    for _ in range(20):
        esc.poll(0.05)
    rcvbuf = esc.bus.socket.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)  # Linux reports twice the request
    print(json.dumps({"raw": list(esc.raw) if esc.raw else None, "applied": esc.commands,
                      "rejects": esc.summary()["rejects"], "rcvbuf": rcvbuf}))
    tx.shutdown()
    esc.bus.shutdown()


if __name__ == "__main__":
    main()
