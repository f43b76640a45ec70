"""Atomic output files: a temporary file in the same folder, then an atomic rename."""
from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path





@contextlib.contextmanager
def atomic_write(path, mode="wb", **open_kwargs):
    """Open a temporary file next to ``path`` and rename it over ``path`` on success.

    Parameters
    ----------
    path : str or Path
        Destination file; its folder must exist (it is created if missing).
    mode : str
        ``"wb"`` or ``"w"`` (text); extra keyword arguments go to :func:`open`.

    Yields
    ------
    file object
        Write to it; on an exception the temporary file is removed and ``path`` is
        left as it was.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "out.txt"
    >>> with atomic_write(p, "w") as f:
    ...     _ = f.write("done")
    >>> p.read_text()
    'done'
    """
    path = Path(path)
    if mode not in ("wb", "w"):
        raise ValueError(f"mode must be 'wb' or 'w', got {mode!r}")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, mode, **open_kwargs) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


# =====================================================================================
# Image sequences
# =====================================================================================

#: File extensions :func:`read_sequence` picks up when given a folder.