"""Command-line options of the DroneCAN actuator path, shared by `hil run`, `sim`, `autopilot`, `soak`."""

from __future__ import annotations

import argparse
import json


def add_can_arguments(p: argparse.ArgumentParser, actuators: bool = True) -> None:
    g = p.add_argument_group("CAN actuators (DroneCAN over python-can)")
    if actuators:
        g.add_argument("--actuators", choices=("mavlink", "can"), default=None,
                       help="thruster set-points as HIL_ACTUATOR_CONTROLS over UDP (mavlink) or as DroneCAN "
                            "ESC RawCommand over CAN with ESC Status back (can) (default: can.actuators = mavlink)")
    g.add_argument("--can-interface", metavar="NAME", default=None,
                   help="python-can interface of the bus, e.g. socketcan, virtual, pcan (default: can.interface = socketcan)")
    g.add_argument("--can-channel", metavar="CHANNEL", default=None,
                   help="python-can channel of the bus, e.g. vcan0, can0 (default: can.channel = vcan0)")


def can_overrides(args: argparse.Namespace) -> list[str]:
    """The CAN options as ``--set`` overrides (validated by the configuration loader)."""
    out = []
    if getattr(args, "actuators", None) is not None:
        out.append("can.actuators=" + json.dumps(args.actuators))
    if args.can_interface is not None:
        out.append("can.interface=" + json.dumps(args.can_interface))
    if args.can_channel is not None:
        out.append("can.channel=" + json.dumps(args.can_channel))
    return out
