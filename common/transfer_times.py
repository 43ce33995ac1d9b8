"""(transfer ID, time) of each DroneCAN transfer sent or applied, for command-to-applied latency.

An hour at 100 Hz is 360,000 pairs, 3.2 MB: kept in memory they would be most of what a soak
measures as resident-memory growth. With :meth:`TransferTimes.spill_to`, pairs are written to two
raw files in chunks of :attr:`TransferTimes.CHUNK`, so memory stays constant; :meth:`arrays` and
:meth:`save` read them back.
"""

from __future__ import annotations

import os
from array import array
from typing import IO, TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np


class TransferTimes:
    """Records only while :attr:`enabled`; times in seconds of whatever clock the caller uses."""

    CHUNK = 4096

    def __init__(self) -> None:
        self.enabled = False
        self.tid = array("b")
        self.at = array("d")
        self.count = 0
        self._spill: tuple[IO[bytes], IO[bytes]] | None = None
        self._spill_path: str | None = None

    def start(self, spill_to: str | None = None) -> None:
        """Record from now on; ``spill_to``: stream to ``spill_to + ".tid"`` / ``".at"`` files."""
        self.enabled = True
        if spill_to is not None and self._spill is None:
            self._spill_path = spill_to
            self._spill = (open(spill_to + ".tid", "wb"), open(spill_to + ".at", "wb"))

    def add(self, tid: int, t: float) -> None:
        if not self.enabled:
            return
        self.tid.append(tid)
        self.at.append(t)
        self.count += 1
        if self._spill is not None and len(self.tid) >= self.CHUNK:
            self._flush()

    def _flush(self) -> None:
        assert self._spill is not None
        self.tid.tofile(self._spill[0])
        self.at.tofile(self._spill[1])
        del self.tid[:]
        del self.at[:]

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """All pairs so far as numpy arrays (int8 transfer IDs, float64 times)."""
        import numpy as np

        tid, at = np.frombuffer(self.tid, dtype=np.int8), np.frombuffer(self.at, dtype=float)
        if self._spill is None:
            return tid.copy(), at.copy()
        for fh in self._spill:
            fh.flush()
        assert self._spill_path is not None
        old_tid = np.fromfile(self._spill_path + ".tid", dtype=np.int8)
        old_at = np.fromfile(self._spill_path + ".at", dtype=float)
        return np.concatenate([old_tid, tid]), np.concatenate([old_at, at])

    def save(self, path: str) -> None:
        """All pairs as an .npz (``tid``, ``at``); the spill files are removed."""
        import numpy as np

        tid, at = self.arrays()
        np.savez(path, tid=tid, at=at)
        self.close()

    def close(self) -> None:
        if self._spill is None:
            return
        for fh in self._spill:
            fh.close()
        for ext in (".tid", ".at"):
            try:
                os.unlink(str(self._spill_path) + ext)
            except OSError:
                pass
        self._spill = None
