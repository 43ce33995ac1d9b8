"""Files the hil commands write: JSON summaries, atomically."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


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
