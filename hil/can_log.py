"""The run folder's CAN log: every frame on the bus, in candump's .log format (can.LogReader reads it).

The orchestrator opens its own python-can bus on the run's channel (SocketCAN delivers every frame
to every socket on the interface) and records with python-can's own writer, so the file is what
``candump -L`` would have written and ``can.LogReader`` / ``canplayer`` read back.
"""

from __future__ import annotations

from pathlib import Path
from typing import TypedDict

import can

from common.can_params import CanParams, open_bus


class CanLogSummary(TypedDict):
    can_log: str              # the file
    can_log_frames: int       # frames recorded


class CanRecorder:
    """Records every frame of the configured bus to ``path`` until :meth:`close`."""

    def __init__(self, params: CanParams, path: Path) -> None:
        self.path = path
        self.bus = open_bus(params, receive_own_messages=False)
        self.frames = 0
        self.writer = can.Logger(str(path))
        self.notifier = can.Notifier(self.bus, [self.writer, self._count], timeout=0.1)

    def _count(self, _msg: can.Message) -> None:
        self.frames += 1

    def close(self) -> CanLogSummary:
        self.notifier.stop(timeout=2.0)
        self.writer.stop()
        self.bus.shutdown()
        return CanLogSummary(can_log=str(self.path), can_log_frames=self.frames)
