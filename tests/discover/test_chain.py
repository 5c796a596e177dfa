"""Discovery through the whole measurement chain (markers -> mocapfj joints -> angles ->
deflection) on 30 s trials of the concealed-effect suite; the full 60 s suite with validation
trials is benchmarks/bench_discover.py (table in docs/discovery.md)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from mocapfj.cli import main

ROOT = Path(__file__).resolve().parents[2]


def _bundle(tmp_path_factory, path: Path, duration: float) -> Path:
    from mocapfj.synth.record import record_scenario, write_scenario_bundle
    from mocapfj.synth.scenario import load_scenario

    d = tmp_path_factory.mktemp(path.stem) / "bundle"
    write_scenario_bundle(record_scenario(load_scenario(path).with_duration(duration), with_concealment=False), d)
    return d


def _search(bundle: Path, model: Path, out: Path):
    """Discovery's search alone (no output-error simulation), on the bundle's signals."""
    import mocapfj
    from mocapfj.discover import discover, read_model_file

    sig = mocapfj.signals(bundle)
    models = read_model_file(model)
    return discover(sig, {n: models[n] for n in sig}, fs_hz=250.0, simulate=False)


@pytest.mark.parametrize("label", ["control", "time_delay", "two_effects"])
def test_search_through_the_chain(label, tmp_path_factory):
    """control: nothing found; time_delay: named first and estimated within 0.5 ms of the planted
    1.0 ms; two_effects (Bouc-Wen hysteresis + friction asymmetry): both found, on j2."""
    path = ROOT / "datasets" / ("discovery" if label == "two_effects" else "suite") / f"{label}_ident.toml"
    b = _bundle(tmp_path_factory, path, 30.0)
    d = _search(b, path, b.parent / "joints")
    found = [(e["name"], e["joint"]) for e in d.effects]
    print(label, found, [e["parameters"] for e in d.effects], [e["p_value"] for e in d.effects])
    if label == "control":
        assert found == []
    elif label == "time_delay":
        assert found[0] == ("time_delay", "j2")
        assert abs(d.effects[0]["parameters"]["delay_s"] - 1.0e-3) < 0.5e-3
    else:
        assert {("hysteresis", "j2"), ("friction_asymmetry", "j2")} <= set(found)
        asym = next(e for e in d.effects if e["name"] == "friction_asymmetry")["parameters"]
        assert asym["c_pos"] > asym["c_neg"]        # planted 11.0 / 7.6 N m


def test_cli_discover_with_validation(tmp_path_factory, capsys):
    """`mocapfj discover` end to end on 20 s hysteresis trials: the JSON keys of the issue, the
    effect named with an explanation, the augmented model file readable, the fit improving on
    the trial and on the validation trial."""
    from mocapfj.discover import read_model_file
    from mocapfj.io import read_csv_columns

    ident = _bundle(tmp_path_factory, ROOT / "datasets" / "suite" / "hysteresis_ident.toml", 20.0)
    valid = _bundle(tmp_path_factory, ROOT / "datasets" / "suite" / "hysteresis_valid.toml", 20.0)
    out = ident.parent / "out"
    model = ROOT / "datasets" / "suite" / "hysteresis_ident.toml"
    assert main(["discover", str(ident), "--out", str(out), "--model", str(model), "--validation", str(valid),
                 "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert {"effects", "fit_before", "fit_after", "validation"} <= set(s)
    e = s["effects"][0]
    assert {"name", "joint", "explanation", "location", "parameters", "p_value", "fit_gain_pct"} <= set(e)
    assert (e["name"], e["joint"]) == ("hysteresis", "j2") and "hysteresis" in e["explanation"]
    assert e["p_value"] < 1e-10 and e["fit_gain_pct"] > 0
    assert s["fit_after"]["j2"] > s["fit_before"]["j2"]
    v = s["validation"]
    assert v["fit_after"]["j2"] > v["fit_before"]["j2"]
    assert [(x["name"], x["joint"]) for x in v["effects"]] == [("hysteresis", "j2")] and v["effects"][0]["fit_gain_pct"] > 0
    augmented = read_model_file(out / "model.toml")["j2"]
    assert type(augmented.spring).__name__ == "BoucWen"
    cols = read_csv_columns(out / "residuals.csv")
    assert {"t", "j2_r_delta_before", "j2_r_u_after"} <= set(cols)


def test_cli_discover_against_the_model_identified_on_the_spot(tmp_path_factory, capsys):
    """Without --model each joint is identified on the trial (motor-first, linear spring); on the
    no-effect control nothing is missing."""
    b = _bundle(tmp_path_factory, ROOT / "datasets" / "suite" / "control_ident.toml", 20.0)
    assert main(["discover", str(b), "--out", str(b.parent / "out"), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["model"] == "identified" and s["effects"] == [] and s["verdict"] == "no missing physics found"
    assert s["fit_after"] == s["fit_before"]


def test_a_mismatch_outside_the_library_is_reported_not_hidden(tmp_path_factory, capsys):
    """pa10_joints23 (joints 2 and 3 coupled through the URDF's mass matrix and the elbow's gravity,
    which depends on q2 + q3) against single-joint models identified on the spot: no effect of
    the library explains it, and the verdict says so, with the residual (measured: link residuals
    13.6 and 7.3 N m RMS against thresholds of 1.6 and 0.8 N m on the 30 s trial; with the
    output-error parameters the spring residuals, 4.8 and 3.5 N m, are named too), instead of
    "no missing physics found"."""
    b = _bundle(tmp_path_factory, ROOT / "datasets" / "pa10_joints23.toml", 20.0)
    assert main(["discover", str(b), "--out", str(b.parent / "out"), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["remaining"]["j2"]["link_unexplained"] and s["remaining"]["j3"]["link_unexplained"]
    assert "a mismatch no effect of the library explains remains on" in s["verdict"]
    assert "j2 (link residual" in s["verdict"] and "j3 (link residual" in s["verdict"]


def _children(pid: int) -> list[int]:
    import os

    out = []
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                with open(f"/proc/{d}/stat", "rb") as f:
                    if int(f.read().rsplit(b")", 1)[1].split()[1]) == pid:
                        out.append(int(d))
            except (OSError, IndexError, ValueError):
                pass
    return out


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the worker is forked on Linux only")
def test_ctrl_c_while_the_worker_runs_leaves_no_process_and_nothing_written(tmp_path_factory):
    """Ctrl-C (SIGINT to the terminal's process group) while the re-identification runs in its
    worker: one line, exit 130, no traceback from either process, no process left, no output."""
    import os
    import signal
    import subprocess
    import time

    ident = _bundle(tmp_path_factory, ROOT / "datasets" / "suite" / "hysteresis_ident.toml", 20.0)
    out = ident.parent / "out"
    p = subprocess.Popen([sys.executable, "-m", "mocapfj.cli", "discover", str(ident), "--out", str(out), "--model",
                          str(ROOT / "datasets" / "suite" / "hysteresis_ident.toml")],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    # (a suite started in the background inherits SIGINT ignored, and a Python started so keeps it)
    deadline = time.monotonic() + 120
    while not _children(p.pid) and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert p.poll() is None and _children(p.pid), "no worker seen before the run ended"
    os.killpg(p.pid, signal.SIGINT)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 130 and err.count("\n") == 1 and "interrupted" in err and "Traceback" not in err, err
    time.sleep(1.0)
    try:
        os.killpg(p.pid, 0)                              # anyone left in the group
        left = True
    except ProcessLookupError:
        left = False
    assert not left and not out.exists()
