"""Cholesky factorisation of the response solve's small normal matrices, on one thread.

OpenBLAS's ``dpotrf`` (behind ``scipy.linalg.cho_factor``) spreads even a 256 x 256
factorisation over its threads. It takes 0.5 ms on an idle machine, but on this shared
2-core machine, while another process kept the other core busy, the call waited up to
170 ms for its worker thread (5 of 40 calls over 5 ms). LAPACK's unblocked ``dpotf2``
runs on the calling thread and is as fast up to 256 levels (0.49 ms against 0.46 ms);
above that the blocked, threaded ``dpotrf`` wins (384: 1.7 against 0.7 ms; 1024, the
16-bit solve: 33 against 12 ms), so larger matrices still go to ``cho_factor``.

``dpotf2`` is reached through SciPy's Cython LAPACK (``scipy.linalg.cython_lapack``, a
public API exporting every routine as a C function pointer); where it is missing or its
signature is not the expected one, every size goes to ``cho_factor``.
"""

from __future__ import annotations

import ctypes

import numpy as np
import scipy.linalg

UNBLOCKED_MAX = 256
"""Largest matrix factored by ``dpotf2`` on the calling thread."""

_INT_P = ctypes.POINTER(ctypes.c_int)
_DOUBLE_P = ctypes.POINTER(ctypes.c_double)
_POTF2_SIGNATURE = b"void (char *, int *, __pyx_t_5scipy_6linalg_13cython_lapack_d *, int *, int *)"


def _cython_lapack(name: str, signature: bytes, prototype: type) -> object | None:
    """The function ``name`` of ``scipy.linalg.cython_lapack``, if its C signature matches."""
    try:
        import scipy.linalg.cython_lapack as cython_lapack

        capsule = cython_lapack.__pyx_capi__[name]
    except (ImportError, AttributeError, KeyError):
        return None
    api = ctypes.pythonapi
    get_name = ctypes.PYFUNCTYPE(ctypes.c_char_p, ctypes.py_object)(("PyCapsule_GetName", api))
    get_pointer = ctypes.PYFUNCTYPE(ctypes.c_void_p, ctypes.py_object, ctypes.c_char_p)(
        ("PyCapsule_GetPointer", api))
    capsule_name = get_name(capsule)
    if capsule_name != signature:
        return None
    return prototype(get_pointer(capsule, capsule_name))


_potf2 = _cython_lapack("dpotf2", _POTF2_SIGNATURE, ctypes.CFUNCTYPE(
    None, ctypes.c_char_p, _INT_P, _DOUBLE_P, _INT_P, _INT_P))


def cholesky_factor(matrix: np.ndarray) -> tuple[np.ndarray, bool]:
    """Factor the symmetric positive definite ``matrix`` (overwritten), as ``cho_factor``.

    Returns ``(factor, lower)`` for ``scipy.linalg.cho_solve`` and LAPACK's ``dpocon``.
    Raises :class:`numpy.linalg.LinAlgError` if ``matrix`` is not positive definite.
    """
    n = matrix.shape[0]
    if _potf2 is None or n > UNBLOCKED_MAX or not matrix.flags.c_contiguous:
        return scipy.linalg.cho_factor(matrix, lower=True, overwrite_a=True, check_finite=False)
    # Symmetric, so the C-ordered array is also the matrix in Fortran order; dpotf2 writes
    # L in its Fortran lower triangle, which the Fortran-ordered view matrix.T presents.
    size, info = ctypes.c_int(n), ctypes.c_int(0)
    _potf2(b"L", ctypes.byref(size), matrix.ctypes.data_as(_DOUBLE_P), ctypes.byref(size),
           ctypes.byref(info))
    if info.value != 0:
        raise np.linalg.LinAlgError(f"the matrix is not positive definite (minor {info.value})")
    return matrix.T, True
