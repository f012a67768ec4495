"""Atomic file writes: every file the package writes goes through a temporary file and a rename.

A reader (or a run resumed after a kill) sees the old file or the new one,
never a half-written one. The temporary file sits in the destination's
folder (a rename across file systems is not atomic) and keeps the
destination's suffix, because matplotlib and imageio choose the format from
the name they are given.
"""

from __future__ import annotations

import os
import pathlib
import tempfile
from collections.abc import Callable


def write_atomic_with(path: str | os.PathLike, write: Callable[[str], None]) -> None:
    """Lets ``write`` fill a temporary file, then renames it to ``path``.

    Args:
      path: Destination file; parent directories are created.
      write: Called with the temporary file's path (same folder and suffix as ``path``); it writes the
        whole file there. If it raises, the temporary file is removed and ``path`` is left as it was.
    """
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=path.suffix)
    os.close(fd)
    try:
        write(tmp)
        os.chmod(tmp, 0o644)  # mkstemp makes it owner-only; written files are readable like any new file
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def write_atomic(path: str | os.PathLike, data: bytes, fsync: bool = False) -> None:
    """Writes ``data`` to ``path`` through a temporary file and a rename.

    Args:
      path: Destination file; parent directories are created.
      data: The file's bytes.
      fsync: Whether the bytes reach the disk before the rename (checkpoints: a power cut leaves the old
        file or the new one, never an empty one); off for the many small files of a dataset.
    """

    def write(tmp: str) -> None:
        with open(tmp, "wb") as f:
            f.write(data)
            if fsync:
                f.flush()
                os.fsync(f.fileno())

    write_atomic_with(path, write)
