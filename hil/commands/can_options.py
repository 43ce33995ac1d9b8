"""Command-line options of the DroneCAN actuator path, shared by `hil run`, `sim`, `autopilot`, `soak`."""

from __future__ import annotations

import argparse
import json
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from hil.settings import HilConfig


def add_can_arguments(p: argparse.ArgumentParser, actuators: bool = True, default: str = "can.actuators = mavlink"
                      ) -> None:
    """The CAN options; ``default`` is what --help says --actuators defaults to (a command may set its own)."""
    g = p.add_argument_group("CAN actuators (DroneCAN over python-can)")
    if actuators:
        g.add_argument("--actuators", choices=("mavlink", "can"), default=None,
                       help="thruster set-points as HIL_ACTUATOR_CONTROLS over UDP (mavlink) or as DroneCAN "
                            "ESC RawCommand over CAN with ESC Status back (can) (default: " + default + ")")
    g.add_argument("--can-interface", metavar="NAME", default=None,
                   help="python-can interface of the bus, e.g. socketcan, pcan, kvaser "
                        "(default: can.interface = socketcan); "
                        "it must reach across processes, so python-can's in-process 'virtual' is refused")
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


# python-can interfaces whose bus exists only inside one process: the simulator's ESCs and the
# autopilot are separate processes, so over these they would never hear each other.
IN_PROCESS_ONLY = ("virtual",)


def check_can(cfg: HilConfig, what: str) -> None:
    """Refuse, with the reason, a CAN set-up that cannot work across processes or does not exist here
    (``UsageError``, exit 2), before anything is started. ``what`` names the command for the message."""
    from hil.errors import UsageError

    can_cfg = cfg.can
    if can_cfg.actuators != "can":
        return
    if cfg.sim.lockstep_pipeline:
        from simulator.server import PIPELINE_NOT_WITH_CAN

        raise UsageError(f"sim.lockstep_pipeline (--pipeline): {PIPELINE_NOT_WITH_CAN}; drop one of the two")
    if can_cfg.interface in IN_PROCESS_ONLY:
        raise UsageError(f"--can-interface {can_cfg.interface}: python-can's {can_cfg.interface!r} bus exists only "
                         f"inside one process, and {what} puts the ESCs and the autopilot in separate processes, "
                         f"so no command would ever arrive; use socketcan on vcan0 "
                         f"(`hil vcan -- hil run --actuators can`) or a real CAN interface")
    if can_cfg.interface == "socketcan":
        import os
        import socket

        try:
            socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
        except (OSError, AttributeError) as exc:
            reason = getattr(exc, "strerror", None) or exc
            raise UsageError(f"--actuators can: this kernel has no SocketCAN ({reason}); "
                             f"run inside `hil vcan -- hil ...`, which provides vcan0 (natively or in User-Mode "
                             f"Linux), or choose another --can-interface") from None
        if not os.path.exists(f"/sys/class/net/{can_cfg.channel}"):
            raise UsageError(f"--actuators can: there is no CAN interface {can_cfg.channel!r} on this machine; create "
                             f"it (`ip link add dev {can_cfg.channel} type vcan; ip link set up {can_cfg.channel}`, "
                             f"as root) or run inside `hil vcan -- hil ...`")
