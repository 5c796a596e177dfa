"""Results that depend on a recording alone, kept across the many simulations discovery compares
with one recording.

Discovery simulates dozens of candidate models on one recording (the refits of the weak effects,
the held-out gates, the re-identification's judgement). Each comparison needs the excitation's
period, the Wiener-filtered drive and the white floors of the recorded signals, which depend on
the recording and not on the model: computed once per recording here, they took about three
quarters of a 60 s comparison (0.16 s of 0.2 s at 250 Hz). The key is the arrays' contents (a
BLAKE2 digest of their bytes, shapes and dtypes) and the other arguments, so a recording cut or
resampled is a new key. The arrays returned are read-only: a caller cannot change what the next
caller gets.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from functools import wraps

import numpy as np

__all__ = ["by_content", "wiener_drive_of", "spline_rates"]


def _key(args, kwargs) -> bytes:
    h = hashlib.blake2b(digest_size=20)
    for a in list(args) + sorted(kwargs.items()):
        if isinstance(a, tuple) and len(a) == 2 and isinstance(a[0], str):       # a keyword
            h.update(a[0].encode())
            a = a[1]
        if isinstance(a, np.ndarray):
            a = np.ascontiguousarray(a)
            h.update(f"{a.dtype.str}{a.shape}".encode())
            h.update(a.tobytes())
        else:
            h.update(repr(a).encode())
        h.update(b"|")
    return h.digest()


def by_content(size: int = 16):
    """Memoise a pure function of arrays and scalars by the contents of its arguments (module
    docstring), keeping the `size` latest results."""

    def wrap(fn):
        store: OrderedDict = OrderedDict()

        @wraps(fn)
        def call(*args, **kwargs):
            k = _key(args, kwargs)
            if k in store:
                store.move_to_end(k)
                return store[k]
            out = fn(*args, **kwargs)
            if isinstance(out, np.ndarray):
                out = out.copy()
                out.setflags(write=False)
            store[k] = out
            if len(store) > size:
                store.popitem(last=False)
            return out

        call.cache_clear = store.clear
        return call

    return wrap


@by_content()
def wiener_drive_of(q_m, fs):
    """The Wiener-filtered motor angle that drives a simulation (:func:`mocapfj.ident.output_error.wiener_drive`),
    computed once per content."""
    from ..ident.output_error import wiener_drive

    return wiener_drive(q_m, fs)


@by_content()
def spline_rates(t, drive):
    """(velocity, acceleration) (T,) of the cubic spline through the drive's samples."""
    from scipy.interpolate import CubicSpline

    spline = CubicSpline(t, drive)
    return np.stack([spline(t, 1), spline(t, 2)])
