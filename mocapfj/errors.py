"""The one exception type for bad input, and the message shape every reader uses.

Every reader validates at the boundary and raises :class:`InputError` naming the file, the field
and what was expected (and what came, when that helps). The CLI prints ``str(error)`` on one line
and exits with code 2.
"""

from __future__ import annotations

from os import PathLike

__all__ = ["InputError", "not_utf8"]


class InputError(ValueError):
    """Bad input: a file, a field in it, what was expected and what came.

    Attributes
    ----------
    file : str
        The file (or directory) the problem is in; ``"<argument>"`` for a Python argument.
    field : str
        The field, column, key or marker label.
    expected : str
        What a valid input has there.
    got : str or None
        What the input had instead, when known.
    hint : str or None
        What would fix it, when that is not obvious from `expected`.
    """

    def __init__(
        self,
        file: str | PathLike[str] | None,
        field: str,
        expected: str,
        got: object = None,
        hint: str | None = None,
    ) -> None:
        self.file = str(file) if file is not None else "<argument>"
        self.field = field
        self.expected = expected
        self.got = None if got is None else str(got)
        self.hint = hint
        msg = f"{self.file}: {field}: expected {expected}"
        if self.got is not None:
            msg += f", got {self.got}"
        if hint:
            msg += f" ({hint})"
        super().__init__(" ".join(msg.split()))  # always one line


def not_utf8(path, e: UnicodeDecodeError) -> InputError:
    """The InputError for a file that is not UTF-8 text: where, and which byte (never the text)."""
    return InputError(path, f"byte {e.start}", "UTF-8 text", f"byte 0x{e.object[e.start]:02x}",
                      hint="save the file as UTF-8")
