"""The one engine switch: compiled (numba) kernels or their numpy/OpenCV twins.

Each stage module defines a numba kernel next to the numpy code that computes the same
thing; :func:`jit` compiles the kernel when numba is importable, and every stage asks
:func:`use_numba` at call time which one to run (as trackpy's ``try_numba``). Set
``WINGPHOTO_NO_NUMBA=1`` before the import to never import numba, or call
``try_numba(False)`` at run time (the tests compare both engines this way).
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

try:  # pragma: no cover - depends on the environment
    if os.environ.get("WINGPHOTO_NO_NUMBA"):
        raise ImportError
    import numba as _numba
except ImportError:  # pragma: no cover
    _numba = None

#: True when numba could be imported (the kernels are compiled).
NUMBA_AVAILABLE = _numba is not None
#: The modules that hold compiled kernels or constants the kernels read. numba keys a
#: kernel's cache by its own file only, so a kernel that calls another module's kernel
#: (predict -> geometry) or reads its constant (refine -> options) would keep running a
#: stale copy after that module changed; :func:`clear_stale_caches` prevents it.
KERNEL_MODULES = ("audit", "background", "engine", "fastpath", "geometry", "hop", "match", "options", "predict", "refine", "sigma", "status")
_enabled = NUMBA_AVAILABLE
_fast_frames = True


def clear_stale_caches(package_dir=None, modules=KERNEL_MODULES):
    """Delete numba's in-tree caches of the package when any kernel module's source changed.

    A hash of the sources of ``modules`` is kept beside the caches
    (``__pycache__/wingphoto-kernels.sha256``); when it differs, every ``*.nbi``/``*.nbc``
    file there is deleted and the kernels compile afresh (once, ~1 min). Written by hand:
    numba's own invalidation looks at one file per kernel. A read-only install (no
    in-tree cache) is left alone.

    Parameters
    ----------
    package_dir : path-like, optional
        The package folder (default: this one).
    modules : sequence of str
        Module names (without ``.py``) whose sources make the hash.

    Returns
    -------
    bool
        True when caches were cleared.
    """
    here = Path(package_dir) if package_dir is not None else Path(__file__).parent
    digest = hashlib.sha256()
    for name in modules:
        try:
            digest.update((here / f"{name}.py").read_bytes())
        except OSError:
            digest.update(name.encode())
    key = digest.hexdigest()
    cache = here / "__pycache__"
    stamp = cache / "wingphoto-kernels.sha256"
    try:
        if stamp.read_text() == key:
            return False
    except OSError:
        pass
    try:
        cache.mkdir(exist_ok=True)
        for f in list(cache.glob("*.nbi")) + list(cache.glob("*.nbc")):
            f.unlink(missing_ok=True)
        tmp = stamp.with_name(f"{stamp.name}.{os.getpid()}.tmp")
        tmp.write_text(key)
        os.replace(tmp, stamp)
    except OSError:  # pragma: no cover - a read-only install: numba caches elsewhere
        return False
    return True


if NUMBA_AVAILABLE:
    clear_stale_caches()


def jit(fn=None, **kw):
    """Compile ``fn`` with ``numba.njit(cache=True, nogil=True, error_model="numpy", **kw)`` when numba is
    available; otherwise return it unchanged (it is then only called by tests)."""
    if fn is None:
        return lambda f: jit(f, **kw)
    if _numba is None:
        return fn
    # error_model="numpy": a division by zero gives inf/NaN as in numpy (a blank or
    # half-black frame), not a ZeroDivisionError
    return _numba.njit(cache=True, nogil=True, error_model="numpy", **kw)(fn)


def use_numba():
    """True when the compiled kernels are to be used."""
    return _enabled


def try_numba(enable=True):
    """Use the compiled kernels (if numba is installed) or the numpy twins.

    Parameters
    ----------
    enable : bool
        False forces the numpy/OpenCV code.

    Returns
    -------
    bool
        Whether the compiled kernels are now in use.
    """
    global _enabled
    _enabled = bool(enable) and NUMBA_AVAILABLE
    return _enabled


def use_fast_frames():
    """True when steady frames are to run through the compiled fast frame
    (:mod:`wingphoto.track.fastpath`): the compiled kernels are in use and
    :func:`try_fast_frames` did not turn it off."""
    return _enabled and _fast_frames


def try_fast_frames(enable=True):
    """Run steady frames through the compiled fast frame (default with numba) or always
    through the stage-by-stage :meth:`~wingphoto.track.tracker.Tracker.step`.

    The tracks are identical either way (``tests/test_track_fastpath.py``); this switch
    is for that test and for profiling the stages.

    Parameters
    ----------
    enable : bool

    Returns
    -------
    bool
        Whether the fast frame is now in use (it needs the compiled kernels).
    """
    global _fast_frames
    _fast_frames = bool(enable)
    return use_fast_frames()
