"""An output a command could not finish is removed: `removed_if_unfinished`.

A command that writes a new file or bag directory (``export``, ``import tdm``, ``replay
--offline``) and fails part-way (a full disk, an interrupt) leaves nothing behind, so a
re-run with the same output path is not refused ("exists already") and no reader meets a
torn file. Outputs that existed before are never touched (the commands refuse those).
"""

from __future__ import annotations

import contextlib
import shutil
from collections.abc import Iterator
from pathlib import Path


@contextlib.contextmanager
def removed_if_unfinished(out: Path) -> Iterator[None]:
    """Remove `out` (a file or a directory) when the block raises, if it did not exist before.

    The exception goes on. The removal itself may fail (a read-only file system): what is
    left is then the command's error message's to name.
    """
    existed = out.exists() or out.is_symlink()
    try:
        yield
    except BaseException:
        if not existed:
            if out.is_dir() and not out.is_symlink():
                shutil.rmtree(out, ignore_errors=True)
            else:
                with contextlib.suppress(OSError):
                    out.unlink()
        raise
