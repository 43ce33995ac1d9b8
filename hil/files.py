"""Files the hil commands write: JSON summaries, atomically."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def write_json_atomic(path: str | Path, data: dict, private: bool = False) -> None:
    """Write JSON to ``path`` via a temporary file and rename: never a half-written file. The file is
    owner-only (0600) when ``private`` (a run with a signing key), else readable as the other files of
    a run folder are (0666 less the umask; mkstemp alone would leave it 0600)."""
    from hil.console import to_json

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        if not private:
            umask = os.umask(0)
            os.umask(umask)
            os.fchmod(fd, 0o666 & ~umask)
        with os.fdopen(fd, "w") as fh:
            fh.write(to_json(data) + "\n")
        os.replace(tmp, path)
    except BaseException:  # a full disk, an interrupt: never leave the temporary file behind
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


# What matplotlib's savefig writes (its own list, fixed here so that checking a name imports nothing).
PLOT_SUFFIXES = (".png", ".pdf", ".svg", ".svgz", ".jpg", ".jpeg", ".tif", ".tiff", ".webp", ".eps", ".ps")


def _first_existing(path: Path) -> Path:
    p = path
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def check_output_folder(path: str | Path, option: str) -> Path:
    """``path`` as a folder a command may create and fill, or a UsageError naming ``option``
    (checked before anything runs; nothing is created here)."""
    from hil.errors import UsageError

    path = Path(path)
    if path.exists() and not path.is_dir():
        raise UsageError(f"{option} {path}: is a file, not a folder")
    base = _first_existing(path.absolute())
    if not base.is_dir():
        raise UsageError(f"{option} {path}: {base} is a file, not a folder")
    if not os.access(base, os.W_OK | os.X_OK):
        raise UsageError(f"{option} {path}: {base} is not writable")
    return path


def check_output_file(path: str | Path, option: str, suffixes: tuple[str, ...]) -> Path:
    """``path`` as a file a command may write (its folder created if missing), or a UsageError naming
    ``option``: not a folder, a known suffix, a writable place (checked before anything runs)."""
    from hil.errors import UsageError

    path = Path(path)
    if path.is_dir():
        raise UsageError(f"{option} {path}: is a folder; give a file name ending {suffixes[0]}")
    if path.suffix.lower() not in suffixes:
        raise UsageError(f"{option} {path}: unknown file type {path.suffix or '(none)'}; "
                         f"use one of {', '.join(suffixes)}")
    if path.exists() and not os.access(path, os.W_OK):
        raise UsageError(f"{option} {path}: is not writable")
    check_output_folder(path.parent, option)
    return path


def tidy_failed_start(out: Path, fresh: bool) -> None:
    """After a run that failed: drop the files it left empty (a run.tlog nothing reached), and the
    folder itself when this run made it and nothing is left in it. Logs that say why stay."""
    try:
        for p in out.iterdir():
            if p.is_file() and p.stat().st_size == 0:
                p.unlink()
        if fresh and not any(out.iterdir()):
            out.rmdir()
    except OSError:
        pass   # tidying is a courtesy: the run's own error is what the user must see
