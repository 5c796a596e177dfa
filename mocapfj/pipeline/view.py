"""``mocapfj view RUN_DIR``: the run's rerun recording, (re)built when missing or older than the
results (:func:`mocapfj.viz.rrd.write_run_recording`), opened in the rerun viewer (the ``rerun``
of rerun-sdk: a native window, or with ``web`` a web viewer served over HTTP for a browser,
e.g. from a headless machine)."""

from __future__ import annotations

import socket
import subprocess
import sys
from pathlib import Path
from urllib.parse import quote

from ..errors import InputError

__all__ = ["run_view", "ensure_run_recording", "recording_is_stale", "viewer_command", "web_url",
           "WEB_PORT", "GRPC_PORT"]

WEB_PORT = 9090       # rerun's defaults, passed explicitly so the printed URL matches
GRPC_PORT = 9876
_NOT_RESULTS = ("recording.rrd", "report.html", "report.md")


def _newest_result_mtime(run_dir: Path) -> float:
    """The newest modification time among the run's result files (the recording and the report
    left out; hidden files too)."""
    newest = 0.0
    for p in run_dir.rglob("*"):
        rel = p.relative_to(run_dir)
        if (p.is_file() and rel.parts[0] not in _NOT_RESULTS and not rel.parts[0].startswith(".")
                and rel.parts[0] != "report_files"):
            newest = max(newest, p.stat().st_mtime)
    return newest


def recording_is_stale(run_dir, rrd=None) -> bool:
    """True when RUN_DIR/recording.rrd (or `rrd`) is missing or older than a result file."""
    run_dir = Path(run_dir)
    rrd = run_dir / "recording.rrd" if rrd is None else Path(rrd)
    return not rrd.is_file() or rrd.stat().st_mtime < _newest_result_mtime(run_dir)


def ensure_run_recording(run_dir, *, magnify: float = 1.0, rebuild: bool = False) -> tuple[Path, bool]:
    """(RUN_DIR/recording.rrd, whether it was built now): built when missing, older than the
    results, or `rebuild`. InputError when run_dir is not a run with results."""
    from ..viz.rrd_data import load_run
    from ..viz.rrd import write_recording_file

    run_dir = Path(run_dir)
    rrd = run_dir / "recording.rrd"
    if run_dir.is_dir() and not (rebuild or magnify != 1.0 or recording_is_stale(run_dir, rrd)):
        return rrd, False
    contents = load_run(run_dir)               # refuses a missing directory or one without results
    write_recording_file(contents, rrd, magnify=magnify)
    return rrd, True


def viewer_command(rrd, *, web: bool = False, web_port: int = WEB_PORT, grpc_port: int = GRPC_PORT) -> list[str]:
    """The command that opens `rrd` in the rerun viewer (rerun-sdk's CLI through this Python):
    a native window, or with `web` a web viewer on http://HOST:web_port (rerun's own gRPC proxy
    on grpc_port serves the recording to it)."""
    cmd = [sys.executable, "-m", "rerun", str(rrd)]
    if web:
        cmd += ["--web-viewer", "--web-viewer-port", str(int(web_port)), "--port", str(int(grpc_port))]
    return cmd


def web_url(host: str | None = None, web_port: int = WEB_PORT, grpc_port: int = GRPC_PORT) -> str:
    """The address a browser opens for the web viewer of :func:`viewer_command` on `host`
    (default this machine's name)."""
    host = host or socket.gethostname()
    return f"http://{host}:{web_port}/?url=" + quote(f"rerun+http://{host}:{grpc_port}/proxy", safe="")


def run_view(run_dir, *, web: bool = False, open_viewer: bool = True, magnify: float = 1.0,
             rebuild: bool = False) -> dict:
    """``mocapfj view``: build the recording if needed and open it; returns {recording, built,
    command, url (web only)}. With `open_viewer` the viewer runs in the foreground until closed
    (Ctrl-C stops a web viewer)."""
    if not (magnify > 0):
        raise InputError(None, "--magnify", "a positive factor", magnify)
    rrd, built = ensure_run_recording(run_dir, magnify=magnify, rebuild=rebuild)
    cmd = viewer_command(rrd, web=web)
    out = {"recording": str(rrd), "built": built, "command": cmd, "url": web_url() if web else None}
    if open_viewer:
        if web:
            print(f"web viewer: {out['url']} (Ctrl-C to stop)", flush=True)
        subprocess.run(cmd, check=False)
    return out
