"""Run every benchmarks/bench_*.py in turn and write docs/benchmarks.md.

Each benchmark prints its own table (ratios against peers measured in the same run); this script
runs each as a subprocess with the same Python, shows its output as it comes, and writes one
Markdown file: the machine (CPU, cores, RAM, OS, Python, numpy, date, commit, load), then per
benchmark its command, exit status, wall time and captured stdout (the last lines of stderr when
it failed).

    python benchmarks/run_all.py                      # everything (hours on two cores) -> docs/benchmarks.md
    python benchmarks/run_all.py --only io,clock_offset # a selection -> benchmarks/.cache/benchmarks_partial.md
    python benchmarks/run_all.py --quick              # --quick passed to the benchmarks that have one
    python benchmarks/run_all.py --list

A partial run (--only) does not overwrite docs/benchmarks.md unless --out names it. The file is
written atomically (a temporary file beside it, then renamed). Exit status: 0 when every
benchmark exited 0, else 1.
"""

from __future__ import annotations

import argparse
import datetime as dt
import fnmatch
import os
import platform
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
FULL_OUT = ROOT / "docs" / "benchmarks.md"
PARTIAL_OUT = HERE / ".cache" / "benchmarks_partial.md"


def benchmarks() -> list[Path]:
    return sorted(HERE.glob("bench_*.py"))


def has_quick(script: Path) -> bool:
    """Whether the script's own argument parser declares --quick (read from its source, not guessed)."""
    return re.search(r"""add_argument\(\s*["']--quick["']""", script.read_text(encoding="utf-8")) is not None


def select(scripts: list[Path], only: str | None) -> list[Path]:
    """`only`: comma-separated names or globs, with or without the bench_ prefix (io, bench_io, 'discover*')."""
    if not only:
        return scripts
    pats = [p.strip().removesuffix(".py") for p in only.split(",") if p.strip()]
    return [s for s in scripts if any(fnmatch.fnmatch(s.stem, p) or fnmatch.fnmatch(s.stem.removeprefix("bench_"), p)
                                      for p in pats)]


def _read(path: str) -> str:
    try:
        return Path(path).read_text(encoding="utf-8", errors="replace")
    except OSError:
        return ""


def machine() -> dict:
    """What the numbers were measured on."""
    cpuinfo = _read("/proc/cpuinfo")
    model = next((ln.split(":", 1)[1].strip() for ln in cpuinfo.splitlines() if ln.startswith("model name")),
                 platform.processor() or platform.machine())
    mem = re.search(r"^MemTotal:\s+(\d+) kB", _read("/proc/meminfo"), re.M)
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:                                      # not Linux
        usable = os.cpu_count()
    try:
        import numpy
        np_version = numpy.__version__
    except ImportError:
        np_version = "not installed"
    try:
        commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short=12", "HEAD"], capture_output=True,
                                text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10).stdout.strip()
        commit = (commit + (" (with uncommitted changes)" if dirty else "")) if commit else "unknown"
    except (OSError, subprocess.SubprocessError):
        commit = "unknown"
    load = os.getloadavg() if hasattr(os, "getloadavg") else None
    return {
        "cpu": model,
        "cores": f"{os.cpu_count()} logical, {usable} usable by this process",
        "ram": f"{int(mem.group(1)) / 1024 ** 2:.1f} GiB" if mem else "unknown",
        "os": platform.platform(),
        "python": f"{platform.python_implementation()} {platform.python_version()}",
        "numpy": np_version,
        "date": dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "commit": commit,
        "load": ("load average at start %.2f, %.2f, %.2f (1, 5, 15 min)" % load) if load else "unknown",
    }


def _kill_group(p: subprocess.Popen) -> None:
    try:
        os.killpg(p.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError, AttributeError):
        p.kill()
    p.wait()


def run_one(script: Path, extra: list[str], timeout: float | None) -> dict:
    """Run one benchmark; its stdout is echoed line by line and kept, its stderr kept."""
    cmd = [sys.executable, str(script), *extra]
    t0 = time.perf_counter()
    lines: list[str] = []
    with tempfile.TemporaryFile(mode="w+", encoding="utf-8", errors="replace") as err:
        p = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=err, text=True, errors="replace", bufsize=1,
                             start_new_session=True)          # its own process group: a timeout stops its workers too

        def echo():
            for line in p.stdout:
                print(line, end="", flush=True)
                lines.append(line)

        reader = threading.Thread(target=echo, daemon=True)
        reader.start()
        try:
            status = p.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            _kill_group(p)
            status = "timeout"
        except KeyboardInterrupt:
            _kill_group(p)
            raise
        finally:
            reader.join(timeout=10)
        err.seek(0)
        stderr = err.read()
    return {"script": script, "cmd": cmd, "status": status, "seconds": time.perf_counter() - t0,
            "stdout": "".join(lines), "stderr": stderr}


def _fence(text: str) -> str:
    ticks = "```"
    while ticks in text:
        ticks += "`"
    return f"{ticks}text\n{text.rstrip()}\n{ticks}"


def render(m: dict, results: list[dict], args, selected: list[Path], quick_ok: set[str]) -> str:
    ok = sum(r["status"] == 0 for r in results)
    total = sum(r["seconds"] for r in results)
    scope = "every benchmark" if not args.only else f"a selection (--only {args.only})"
    out = [
        "# Benchmarks",
        "",
        "Written by `python benchmarks/run_all.py` (`make bench`); do not edit by hand. Each section is one",
        "`benchmarks/bench_*.py` as printed in this run: its tables, and the ratios against peers it measured",
        "in the same run on the same machine.",
        "",
        "## Machine",
        "",
        f"- CPU: {m['cpu']}",
        f"- Cores: {m['cores']}",
        f"- RAM: {m['ram']}",
        f"- OS: {m['os']}",
        f"- Python: {m['python']}, numpy {m['numpy']}",
        f"- Date: {m['date']}; commit {m['commit']}",
        f"- {m['load'][0].upper() + m['load'][1:]}",
        "",
        "## Summary",
        "",
        f"Ran {scope}{' with --quick' if args.quick else ''}: {ok} of {len(results)} exited 0, "
        f"{total / 60:.1f} min in all.",
        "",
        "| benchmark | options | exit | wall time |",
        "|---|---|---|---|",
    ]
    for r in results:
        opts = " ".join(r["cmd"][2:]) or "-"
        if args.quick and r["script"].stem not in quick_ok:
            opts += " (no --quick: full run)"
        status = "timed out" if r["status"] == "timeout" else str(r["status"])
        out.append(f"| [{r['script'].stem}](#{r['script'].stem}) | {opts} | {status} | {r['seconds']:.1f} s |")
    not_run = len(selected) - len(results)
    if not_run:
        out += ["", f"{not_run} selected benchmark(s) did not run (interrupted)."]
    for r in results:
        rel = r["script"].relative_to(ROOT)
        status = (f"timed out after {args.timeout:g} s" if r["status"] == "timeout" else f"exit {r['status']}")
        out += ["", f"## {r['script'].stem}", "",
                f"`python {rel}{''.join(' ' + a for a in r['cmd'][2:])}`: {status}, {r['seconds']:.1f} s wall.", ""]
        out.append(_fence(r["stdout"]) if r["stdout"].strip() else "(printed nothing on stdout)")
        if r["status"] != 0 and r["stderr"].strip():
            tail = "\n".join(r["stderr"].rstrip().splitlines()[-30:])
            out += ["", "Last lines of stderr:", "", _fence(tail)]
    return "\n".join(out) + "\n"


def write_atomic(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", default=None, metavar="PATTERN",
                    help="comma-separated benchmark names or globs, bench_ prefix optional: io,'discover*' "
                         "(default: all)")
    ap.add_argument("--quick", action="store_true",
                    help="pass --quick to the benchmarks whose parser has it; the others run in full")
    ap.add_argument("--timeout", type=float, default=None, metavar="S",
                    help="stop a benchmark after S seconds of wall time and go on (default: none)")
    ap.add_argument("--out", type=Path, default=None,
                    help=f"Markdown file (default {FULL_OUT.relative_to(ROOT)}, or "
                         f"{PARTIAL_OUT.relative_to(ROOT)} with --only)")
    ap.add_argument("--list", action="store_true", help="list the benchmarks (and which have --quick) and exit")
    args = ap.parse_args(argv)

    scripts = benchmarks()
    quick_ok = {s.stem for s in scripts if has_quick(s)}
    if args.list:
        for s in scripts:
            print(f"{s.stem}{'  [--quick]' if s.stem in quick_ok else ''}")
        return 0
    selected = select(scripts, args.only)
    if not selected:
        print(f"run_all: --only {args.only!r} matches none of: {', '.join(s.stem for s in scripts)}", file=sys.stderr)
        return 2
    out = args.out or (PARTIAL_OUT if args.only else FULL_OUT)
    m = machine()
    print(f"{len(selected)} benchmark(s) on {m['cpu']} ({m['cores']}), {m['load']}", flush=True)
    results = []
    try:
        for s in selected:
            extra = ["--quick"] if args.quick and s.stem in quick_ok else []
            print(f"\n## {s.stem} {' '.join(extra)}\n", flush=True)
            r = run_one(s, extra, args.timeout)
            results.append(r)
            status = "timed out" if r["status"] == "timeout" else f"exit {r['status']}"
            print(f"-- {s.stem}: {status}, {r['seconds']:.1f} s", flush=True)
            if r["status"] != 0 and r["stderr"].strip():
                print("\n".join(r["stderr"].rstrip().splitlines()[-15:]), file=sys.stderr, flush=True)
    except KeyboardInterrupt:
        print("\nrun_all: interrupted; writing what finished", file=sys.stderr)
    write_atomic(out, render(m, results, args, selected, quick_ok))
    print(f"\nwrote {out} ({sum(r['status'] == 0 for r in results)} of {len(selected)} benchmarks exited 0)")
    return 0 if results and len(results) == len(selected) and all(r["status"] == 0 for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
