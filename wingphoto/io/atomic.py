"""Atomic output files: a temporary file in the same folder, then an atomic rename.

Every output of wingphoto goes through :func:`atomic_write`, so that

- an interrupted or failed write (Ctrl-C, a full disk, an exception while the result is
  being produced) leaves the previous file exactly as it was, and never a half-written one;
- a new file gets the permissions any other program would give it (``0o666`` minus the
  umask), and an overwritten file keeps its mode;
- a destination that is not a regular file (a folder, a FIFO, a device node, a socket)
  is refused with a one-line error instead of being replaced.

:func:`check_output_path` makes the same checks up front, for writers that cannot go
through a file object (e.g. a video encoder that wants a path).
"""
from __future__ import annotations

import contextlib
import errno
import os
import stat
import tempfile
from pathlib import Path

__all__ = ["atomic_write", "check_output_path", "ensure_output_folder", "OutputError"]

#: errno values meaning "the data could not be stored" (rather than a bug in the caller).
_STORAGE_ERRNOS = {
    errno.ENOSPC: "the disk is full",
    errno.EDQUOT: "the disk quota is exceeded",
    errno.EFBIG: "the file is larger than the file system (or a size limit) allows",
    errno.EIO: "an input/output error occurred on the device",
    errno.EROFS: "the file system is read-only",
    errno.EACCES: "permission denied",
    errno.EPERM: "operation not permitted",
}


class OutputError(OSError):
    """An output could not be written; ``str()`` is the one-line message (errno kept)."""

    def __str__(self):
        return self.strerror if self.strerror else super().__str__()


def _kind(mode):
    """Human name of a non-regular file type."""
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode):
        return "a character device"
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def _umask():
    """The process umask, read without changing it where the system allows."""
    with contextlib.suppress(OSError, ValueError):
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    mask = os.umask(0o022)  # no way to read it without setting it elsewhere
    os.umask(mask)
    return mask


def check_output_path(path):
    """Check that ``path`` can be written as an output file and return it resolved.

    Parameters
    ----------
    path : str or Path
        Destination of an output. It may not exist yet; if it exists it must be a
        regular file (a symbolic link to one is followed: the link stays, its target is
        replaced).

    Returns
    -------
    pathlib.Path
        The path to write (the link target for a symbolic link).

    Raises
    ------
    IsADirectoryError
        ``path`` is a folder (or ends with a path separator).
    OSError
        ``path`` is a FIFO, a device node, a socket or anything else but a regular file;
        it is never replaced.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> check_output_path(d / "out.csv") == d / "out.csv"
    True
    >>> try:
    ...     check_output_path(d)
    ... except IsADirectoryError as exc:
    ...     print("refused:", str(exc).split(",")[0].endswith("is a folder"))
    refused: True
    """
    text = os.fspath(path)
    if text == "":
        raise ValueError("the output path is empty; give a file name")
    path = Path(text)
    if text.endswith(("/", os.sep)) or path.name in ("", ".", ".."):
        raise IsADirectoryError(f"output {text} names a folder, not a file; give a file name inside it")
    if path.is_symlink():
        path = Path(os.path.realpath(path))
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return path
    except NotADirectoryError:
        raise NotADirectoryError(
            f"cannot write {text}: a part of its folder path is a file, not a folder; choose another output path"
        ) from None
    except OSError as exc:
        raise OutputError(exc.errno, f"cannot write {text}: {exc.strerror}") from None
    if stat.S_ISREG(st.st_mode):
        return path
    if stat.S_ISDIR(st.st_mode):
        raise IsADirectoryError(
            f"output {text} is a folder, not a file; give the name of a file (inside it or elsewhere)"
        )
    raise OutputError(
        errno.EINVAL,
        f"output {text} is {_kind(st.st_mode)}, not a regular file; wingphoto writes results only to regular "
        "files and will not replace it: choose another output path"
    )


def _storage_error(exc, path):
    """An OSError naming ``path``, what went wrong and that the old file is untouched."""
    why = _STORAGE_ERRNOS.get(exc.errno, exc.strerror or str(exc))
    hint = {
        errno.ENOSPC: "free some space or write elsewhere",
        errno.EDQUOT: "free some space or write elsewhere",
        errno.EROFS: "write elsewhere",
        errno.EACCES: f"check the permissions of {path.parent} or write elsewhere",
        errno.EPERM: f"check the permissions of {path.parent} or write elsewhere",
    }.get(exc.errno, "write elsewhere or retry")
    old = "the existing file is unchanged" if path.exists() else "nothing was written"
    return OutputError(exc.errno, f"cannot write {path}: {why} ({old}); {hint}")


def ensure_output_folder(path):
    """Create the output folder ``path`` (and its parents) unless it exists; return it.

    Raises
    ------
    NotADirectoryError
        ``path`` (or one of its parents) exists and is not a folder: one line naming it.
    OSError
        The folder cannot be created (no permission, read-only file system): one line.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp()) / "results" / "run1"
    >>> ensure_output_folder(d).is_dir()
    True
    """
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        blocker = next((p for p in (path, *path.parents) if p.exists() and not p.is_dir()), path)
        raise NotADirectoryError(
            f"output folder {path} cannot be created: {blocker} exists and is not a folder; choose another "
            "output folder"
        ) from None
    except OSError as exc:
        raise OutputError(exc.errno, f"cannot create the output folder {path}: {exc.strerror}") from None
    return path


@contextlib.contextmanager
def atomic_write(path, mode="wb", **open_kwargs):
    """Open a temporary file next to ``path`` and rename it over ``path`` on success.

    Parameters
    ----------
    path : str or Path
        Destination file; its folder is created if missing. If it exists it must be a
        regular file (or a symbolic link to one, whose target is replaced).
    mode : str
        ``"wb"`` or ``"w"`` (text); extra keyword arguments go to :func:`open`.

    Yields
    ------
    file object
        Write to it; on an exception the temporary file is removed and ``path`` is
        left as it was.

    Raises
    ------
    IsADirectoryError, OSError
        ``path`` is a folder, a FIFO, a device node or another non-regular file (see
        :func:`check_output_path`); nothing is written.
    OSError
        The data could not be stored (a full disk, a read-only file system, no
        permission): one line naming the file; the old file is unchanged.

    Notes
    -----
    A new file gets mode ``0o666 & ~umask``, as ``open`` would give it (``mkstemp``
    alone would give ``0o600``); an overwritten file keeps its mode. The data is flushed
    and ``fsync``-ed before the rename, so after a crash either the old or the new
    content is on disk.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "out.txt"
    >>> with atomic_write(p, "w") as f:
    ...     _ = f.write("done")
    >>> p.read_text()
    'done'
    """
    if mode not in ("wb", "w"):
        raise ValueError(f"mode must be 'wb' or 'w', got {mode!r}")
    path = check_output_path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise NotADirectoryError(
            f"cannot write {path}: {path.parent} exists and is not a folder; choose another output path"
        ) from None
    except OSError as exc:
        raise _storage_error(exc, path) from None
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise _storage_error(exc, path) from None
    try:
        try:
            with os.fdopen(fd, mode, **open_kwargs) as f:
                try:
                    yield f
                except OSError as exc:
                    if exc.errno in _STORAGE_ERRNOS and not isinstance(exc, OutputError):
                        raise _storage_error(exc, path) from exc
                    raise
                f.flush()
                os.fsync(f.fileno())
            try:  # the mode a plain open() would give, or the old file's
                st = os.stat(path)
                perm = stat.S_IMODE(st.st_mode) if stat.S_ISREG(st.st_mode) else None
            except FileNotFoundError:
                perm = 0o666 & ~_umask()
            if perm is not None:
                os.chmod(tmp, perm)
            check_output_path(path)  # it may have been replaced by a folder or FIFO meanwhile
            os.replace(tmp, path)
        except OSError as exc:
            if exc.errno in _STORAGE_ERRNOS and not isinstance(exc, OutputError):
                raise _storage_error(exc, path) from exc
            raise
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
