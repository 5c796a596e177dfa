"""Output directories written whole or not at all.

A run writes into a fresh hidden directory beside ``--out`` and renames it into place when it
completes; on any failure, Ctrl-C or SIGTERM the staging directory is removed, and one left by a
killed run (SIGKILL, power loss) is removed by the next run into the same place. ``--out`` may
not be an input, contain one, or lie inside an input bundle; an existing ``--out`` is replaced
only when it is empty or mocapfj wrote it (the marker file ``.mocapfj-output``).
"""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Iterator, Sequence
from pathlib import Path

from ..errors import InputError

__all__ = ["check_output_dir", "staged_output", "replace_dir", "MARKER"]

MARKER = ".mocapfj-output"
_STAGE = ".mocapfj-tmp"


def _extent(p: Path) -> Path:
    """What an input occupies: a recording.toml stands for its bundle directory."""
    p = p.resolve()
    return p.parent if p.is_file() and p.name == "recording.toml" else p


def check_output_dir(out, inputs: Sequence, option: str = "--out") -> Path:
    """Refuse an output directory that is, contains or lies inside an input, or that holds files
    mocapfj did not write; return it resolved."""
    out_r = Path(out).resolve()
    for parent in out_r.parents:
        if parent.exists() and not parent.is_dir():
            raise InputError(option, "path", "a directory whose parents are directories", f"{parent} is a file")
    for inp in inputs:
        if inp is None:
            continue
        ext = _extent(Path(inp))
        if out_r == ext or ext.is_relative_to(out_r):
            raise InputError(option, "path", "a directory that is not and does not contain an input",
                             f"{out} holds the input {inp}", hint="write the results elsewhere")
        if ext.is_dir() and out_r.is_relative_to(ext):
            raise InputError(option, "path", "a directory outside the input bundles",
                             f"{out} is inside the input {inp}", hint="inputs are never modified")
    if out_r.exists():
        if not out_r.is_dir():
            raise InputError(option, "path", "a directory", f"the file {out}")
        if any(True for _ in out_r.iterdir()) and not (out_r / MARKER).is_file():
            raise InputError(option, "path", "a new or empty directory, or one mocapfj wrote before",
                             f"{out} holds other files", hint="choose a new directory; nothing there is replaced")
    return out_r


def replace_dir(staging: Path, final: Path, old: Path) -> None:
    """Put the finished directory `staging` in place of `final`: the previous one is moved aside to
    `old` and removed only once the new one is there."""
    moved = False
    if final.exists():
        os.replace(final, old)
        moved = True
    os.replace(staging, final)
    if moved:
        shutil.rmtree(old, ignore_errors=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _remove_stale(parent: Path, name: str) -> None:
    """Staging directories of runs into `name` whose process is gone."""
    for d in parent.glob(f".{name}.*{_STAGE}"):
        pid = d.name[len(name) + 2:-len(_STAGE)].split(".")[0]
        if pid.isdigit() and not _alive(int(pid)):
            shutil.rmtree(d, ignore_errors=True)


@contextlib.contextmanager
def staged_output(out) -> Iterator[Path]:
    """Yield a fresh staging directory beside `out`; on success it replaces `out` (an existing
    `out` is set aside first and removed after); on any exception (KeyboardInterrupt, SystemExit
    included) the staging directory is removed and the exception propagates."""
    out = Path(out).resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    _remove_stale(out.parent, out.name)
    stage = out.parent / f".{out.name}.{os.getpid()}{_STAGE}"
    if stage.exists():
        shutil.rmtree(stage)
    try:
        # made inside the try: a Ctrl-C landing between the mkdir and the try left the staging
        # directory behind (tests/test_bad_input.py, under load)
        stage.mkdir()
        yield stage
        (stage / MARKER).write_text("written by mocapfj; a later run into this directory replaces it\n",
                                    encoding="utf-8")
        replace_dir(stage, out, out.parent / f".{out.name}.{os.getpid()}.old{_STAGE}")
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
