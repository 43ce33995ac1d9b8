"""Files the hil commands write: JSON summaries atomically, send/apply time records."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def save_record(path: str, tids, times) -> None:
    """CAN send or apply times (transfer ids, monotonic seconds) as an .npz (hil soak, hil bench can)."""
    import numpy as np

    np.savez(path, tid=np.frombuffer(tids, dtype=np.int8), at=np.frombuffer(times, dtype=float))


def write_json_atomic(path: str | Path, data: dict) -> None:
    """Write JSON to ``path`` via a temporary file and rename: never a half-written file."""
    from hil.console import to_json

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(to_json(data) + "\n")
        os.replace(tmp, path)
    except BaseException:  # a full disk, an interrupt: never leave the temporary file behind
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
