"""A URDF read into a Pinocchio model, with the parser's own messages kept off the terminal.

Pinocchio's URDF parser (urdfdom, C++) prints its errors on the process's stderr before raising,
or prints them and goes on (a mass of "nan"): both become one InputError naming the file and
the parser's first message, and nothing reaches the terminal.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from pathlib import Path

from ..errors import InputError

__all__ = ["build_pin_model"]


@contextlib.contextmanager
def _captured_stderr():
    """File descriptor 2 redirected into a temporary file for the block; yields a function that
    returns what was written."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile(mode="w+b") as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield lambda: (tmp.flush(), tmp.seek(0), tmp.read().decode("utf-8", "replace"))[-1]
        finally:
            os.dup2(saved, 2)
            os.close(saved)


def build_pin_model(urdf) -> "object":
    """A pin.Model from a URDF file path or an XML string (starts with '<'); InputError naming the
    file (or "<URDF string>") and the parser's first message when it fails or complains."""
    import pinocchio as pin

    text = str(urdf)
    is_xml = text.lstrip().startswith("<")
    where = "<URDF string>" if is_xml else text
    if not is_xml and not Path(text).is_file():
        raise InputError(text, "urdf", "an existing URDF file or a URDF XML string", "no such file")
    with _captured_stderr() as said:
        try:
            model = pin.buildModelFromXML(text) if is_xml else pin.buildModelFromUrdf(text)
            error = None
        except (RuntimeError, ValueError) as exc:
            model, error = None, str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        out = said()
    complaints = [ln.strip() for ln in out.splitlines() if "error" in ln.lower()]
    if error is not None or complaints:
        msg = complaints[0] if complaints else error
        raise InputError(where, "urdf", "a valid URDF", " ".join(msg.split())[:200])
    return model
