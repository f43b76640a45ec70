"""The one engine switch: compiled (numba) kernels or their numpy/OpenCV twins.

Each stage module defines a numba kernel next to the numpy code that computes the same
thing; :func:`jit` compiles the kernel when numba is importable, and every stage asks
:func:`use_numba` at call time which one to run (as trackpy's ``try_numba``). Set
``WINGPHOTO_NO_NUMBA=1`` before the import to never import numba, or call
``try_numba(False)`` at run time (the tests compare both engines this way).
"""
from __future__ import annotations

import os

try:  # pragma: no cover - depends on the environment
    if os.environ.get("WINGPHOTO_NO_NUMBA"):
        raise ImportError
    import numba as _numba
except ImportError:  # pragma: no cover
    _numba = None

#: True when numba could be imported (the kernels are compiled).
NUMBA_AVAILABLE = _numba is not None
_enabled = NUMBA_AVAILABLE


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
