"""``mocapfj frf``: a closed-loop multisine CSV (independent simulation, tests/ident/frf_sim.py) ->
JSON with frf / model / modes, frf.json and frf.csv; a recording bundle; bad input as one line and
exit 2 with nothing written."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mocapfj.cli import main
from mocapfj.ident.frf_fit import two_inertia_modes
from mocapfj.ident.multisine import design_multisine
from mocapfj.io.csvio import write_csv_columns

from .frf_sim import simulate_multisine

FS = 1 / 0.003
P = dict(J=0.75, I=1.165, k=1150.0, d=1.0, b=0.8, v=0.3)


@pytest.fixture(scope="module")
def record(tmp_path_factory):
    ms = design_multisine(FS, 1024, 0.5, 12.0, rms=0.01, seed=5)
    u, y, r = simulate_multisine(P, [ms], 6, kp=300.0, kd=30.0, noise_sd=1.0, seed=6)
    d = tmp_path_factory.mktemp("frf")
    cols = {"time": np.arange(u.shape[1]) / FS, "tau": u[0], "qm": y[0], "qref": r[0]}
    write_csv_columns(d / "log.csv", cols)
    return d, cols


def _run(capsys, *argv):
    code = main(["frf", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def test_closed_loop_csv(record, capsys, tmp_path):
    d, _ = record
    code, out, err = _run(capsys, d / "log.csv", "--input", "tau", "--output", "qm", "--reference", "qref",
                          "--out", tmp_path / "o", "--json")
    assert code == 0, err
    s = json.loads(out)
    assert s["period_samples"] == 1024                          # found where the reference repeats
    f = s["frf"]
    for key in ("frequencies_hz", "magnitude", "phase_rad", "coherence", "noise", "distortion"):
        assert key in f
    assert f["estimator"] == "indirect" and len(f["magnitude"]) == len(f["frequencies_hz"])
    m = s["model"]
    assert m["name"] == "two_inertia" and set(m["params"]) == {"J", "I", "k", "d", "b", "v", "g"}
    assert abs(m["params"]["k"]["value"] / P["k"] - 1) < 0.03
    truth = two_inertia_modes(**P)
    assert [x["kind"] for x in s["modes"]] == ["antiresonance", "resonance"]
    for x, (_, f_true, _) in zip(s["modes"], truth):
        assert abs(x["f_hz"] - f_true) < max(4 * x["f_hz_std"], 0.01 * f_true) and x["f_hz_std"] > 0
    assert (tmp_path / "o" / "frf.json").is_file() and (tmp_path / "o" / "frf.csv").is_file()
    code, out, _ = _run(capsys, d / "log.csv", "--input", "tau", "--output", "qm", "--period", 1024 / FS,
                        "--model", "none", "--out", tmp_path / "o2")
    assert code == 0 and "harmonic estimator" in out and "wrote" in out


def test_recording_bundle(record, capsys, tmp_path):
    d, cols = record
    b = tmp_path / "bundle"
    b.mkdir()
    write_csv_columns(b / "controller.csv", {"t_s": cols["time"], "tau": cols["tau"], "qm": cols["qm"],
                                             "qref": cols["qref"]})
    (b / "recording.toml").write_text('format = "mocapfj.recording/1"\nname = "multisine"\n'
                                      '[controller]\nfile = "controller.csv"\ntime_column = "t_s"\n')
    code, out, err = _run(capsys, b, "--input", "tau", "--output", "qm", "--reference", "qref", "--out",
                          tmp_path / "o", "--json")
    assert code == 0, err
    assert abs(json.loads(out)["model"]["params"]["k"]["value"] / P["k"] - 1) < 0.03


def _bad(tmp_path, name, cols):
    write_csv_columns(tmp_path / name, cols)
    return tmp_path / name


def test_bad_input_one_line_exit_2(record, capsys, tmp_path):
    d, cols = record
    n2 = 2 * 1024
    short = _bad(tmp_path, "short.csv", {k: v[:n2] for k, v in cols.items()})
    nan = dict(cols)
    nan["qm"] = cols["qm"].copy()
    nan["qm"][100] = np.nan
    jitter = dict(cols)
    jitter["time"] = cols["time"] + np.r_[0, 0, 0.001, np.zeros(cols["time"].size - 3)]
    noise = dict(cols)
    noise["tau"] = np.random.default_rng(0).normal(size=cols["tau"].size)
    cases = [
        (d / "log.csv", ["--input", "torque"], "--input"),
        (short, [], "periods"),
        (_bad(tmp_path, "nan.csv", nan), [], "'qm'"),
        (_bad(tmp_path, "jitter.csv", jitter), [], "uniform"),
        (d / "log.csv", ["--period", "1.0001"], "--period"),
        (_bad(tmp_path, "noise.csv", noise), ["--reference", None], "period"),
        (tmp_path / "missing.csv", [], "missing.csv"),
    ]
    for path, extra, needle in cases:
        args = {"--input": "tau", "--output": "qm", "--reference": "qref"}
        for k, v in zip(extra[::2], extra[1::2]):
            args[k] = v
        argv = [path] + [x for k, v in args.items() if v is not None for x in (k, v)] + ["--out", tmp_path / "out"]
        code, out, err = _run(capsys, *argv)
        assert code == 2, (path, err)
        assert len(err.strip().splitlines()) == 1 and needle in err, err
        assert not (tmp_path / "out").exists()


def test_period_found_from_a_noisy_input_or_a_ramped_reference():
    from mocapfj.pipeline.frf import find_period

    ms = design_multisine(200.0, 1024, 0.5, 20.0, seed=3)
    t, x = ms.signal(5)
    rng = np.random.default_rng(0)
    assert find_period(x, exact=True) == 1024
    assert find_period(np.clip(t / 8.0, 0, 1) * x, exact=True) == 1024        # ramp longer than the first fifth
    for a in (0.1, 0.3, 0.6):
        assert find_period(x + rng.normal(0, a * x.std(), x.size), exact=False) == 1024
    assert find_period(rng.normal(size=5000), exact=False) is None


def _identify_json(path, params, determined=()):
    """An identify.json of the joint (the keys mocapfj identify writes for params)."""
    doc = {"recordings": ["r"], "joints": [{"name": "j1", "params": {
        n: {"value": v, "std": s, "rel_std_pct": 100 * s / abs(v), "determined": n not in determined,
            **({"reason": "only I + J is determined"} if n in determined else {})}
        for n, (v, s) in params.items()}}]}
    path.write_text(json.dumps(doc))
    return path


def test_compare_with_the_time_domain_identification(record, capsys, tmp_path):
    """The truth as a time-domain result with 1 % SDs agrees; k 10 % off at a 1 % SD is named as a
    disagreement; a parameter identify did not determine is not compared; the modes identify's
    parameters predict are within 1 % of the FRF's (the plant has d = 1, identify's model none)."""
    d, _ = record
    truth = {n: (P[n], 0.01 * P[n]) for n in ("J", "I", "k", "b", "v")}
    good = _identify_json(tmp_path / "good.json", truth, determined=("I",))
    code, out, err = _run(capsys, d / "log.csv", "--input", "tau", "--output", "qm", "--reference", "qref",
                          "--compare", good, "--out", tmp_path / "o", "--json")
    assert code == 0, err
    c = json.loads(out)["comparison"]
    st = {p["name"]: p for p in c["params"]}
    assert st["k"]["status"] == "agree" and st["J"]["status"] == "agree" and abs(st["k"]["z"]) < 3
    assert st["I"]["status"] == "not_compared" and "only I + J" in st["I"]["reason"]
    assert c["disagree"] == [] and c["verdict"].startswith("frf and identify agree on k, J")
    assert [m["kind"] for m in c["modes"]] == ["antiresonance", "resonance"]
    assert all(abs(m["diff_pct"]) < 1.0 for m in c["modes"])
    bad = _identify_json(tmp_path / "bad.json", {**truth, "k": (1.1 * P["k"], 0.01 * P["k"])})
    code, out, err = _run(capsys, d / "log.csv", "--input", "tau", "--output", "qm", "--reference", "qref",
                          "--compare", bad, "--out", tmp_path / "o2")
    assert code == 0, err
    assert "disagree on k" in out and "k: frf" in out and "-9." in out      # about -9 % against identify's k
    code, out, err = _run(capsys, d / "log.csv", "--input", "tau", "--output", "qm", "--single-record",
                          "--compare", good, "--out", tmp_path / "o3")
    assert code == 2 and "compare" in err and err.count("\n") == 1


def test_gravity_stiffness_fitted_compared_or_given(capsys, tmp_path):
    """A link under gravity about its operating point (g = -5 % of k): fitted by default (k within 1 %
    and 4 SDs, g within 4 SDs of the truth); with --compare, the g identify's mglx, mgly imply at
    the record's mean angle is held against it; --gravity-stiffness 0 leaves it in k (5-9 % off);
    a non-finite g is one line, exit 2."""
    g_true = -0.05 * P["k"]
    ms = design_multisine(FS, 1024, 0.5, 12.0, rms=0.01, seed=7)
    u, y, r = simulate_multisine({**P, "g": g_true}, [ms], 6, kp=300.0, kd=30.0, noise_sd=1.0, seed=8)
    write_csv_columns(tmp_path / "log.csv", {"time": np.arange(u.shape[1]) / FS, "tau": u[0], "qm": y[0], "qref": r[0]})
    q0 = float(np.mean(y[0]))
    mglx = -g_true / np.cos(q0)                          # g = -mglx cos q0 - mgly sin q0 with mgly ~ 0
    truth = {n: (P[n], 0.01 * P[n]) for n in ("J", "I", "k", "b", "v")}
    ident = _identify_json(tmp_path / "id.json", {**truth, "mglx": (mglx, 0.02 * abs(mglx)), "mgly": (1e-6, 0.5)})
    args = (tmp_path / "log.csv", "--input", "tau", "--output", "qm", "--reference", "qref")
    code, out, err = _run(capsys, *args, "--compare", ident, "--out", tmp_path / "o", "--json")
    assert code == 0, err
    s = json.loads(out)
    grav = s["gravity"]
    assert s["model"]["gravity_fitted"] and grav["source"].startswith("fitted")
    assert abs(grav["g_Nm_per_rad"] - g_true) < 4 * grav["g_std_Nm_per_rad"], grav
    assert grav["identify"]["value"] == pytest.approx(g_true, rel=1e-6) and "identify's mglx" in grav["identify"]["source"]
    k = s["model"]["params"]["k"]
    assert abs(k["value"] / P["k"] - 1) < 0.01 and abs(k["value"] - P["k"]) < 4 * k["std"], k
    st = {c["name"]: c for c in s["comparison"]["params"]}
    assert st["g"]["status"] == "agree" and st["k"]["status"] == "agree", st
    code, out, err = _run(capsys, *args, "--gravity-stiffness", "0", "--out", tmp_path / "o0", "--json")
    s0 = json.loads(out)
    k0 = s0["model"]["params"]["k"]
    assert code == 0 and 0.05 < k0["value"] / P["k"] - 1 < 0.09, k0
    assert not s0["model"]["gravity_fitted"] and s0["gravity"]["source"].startswith("given")
    code, out, err = _run(capsys, *args, "--gravity-stiffness", "nan", "--out", tmp_path / "o1")
    assert code == 2 and "gravity-stiffness" in err and err.count("\n") == 1, err


@pytest.mark.parametrize("with_reference", [True, False], ids=["reference", "motor_side_only"])
def test_realisations_one_after_another_are_found(tmp_path, capsys, with_reference):
    """Four realisations of 4 periods in one CSV, nothing said about them: the period (2048 samples)
    and the 4 realisations are found, from the reference or from the input alone (where the whole
    record's repeats are hidden by the realisations' changes: the period of its first quarter); k
    within 0.1 % (before: "no line excited", and without the reference a period of 59 samples)."""
    from mocapfj.ident.multisine import multisine_realisations

    ms = design_multisine(FS, 2048, 0.5, 12.0, rms=0.01, seed=5)
    u, y, r = simulate_multisine(P, multisine_realisations(ms, 4, seed=105), 4, kp=300.0, kd=30.0, noise_sd=0.5,
                                 seed=5)
    cols = {"time": np.arange(u.size) / FS, "tau": u.ravel(), "qm": y.ravel()}
    ref = []
    if with_reference:
        cols["qref"] = r.ravel()
        ref = ["--reference", "qref"]
    write_csv_columns(tmp_path / "log.csv", cols)
    code, out, err = _run(capsys, tmp_path / "log.csv", "--input", "tau", "--output", "qm", *ref,
                          "--out", tmp_path / "o", "--json")
    assert code == 0, err
    s = json.loads(out)
    assert s["period_samples"] == 2048 and s["frf"]["n_realisations"] == 4
    assert abs(s["model"]["params"]["k"]["value"] / P["k"] - 1) < 0.001
    assert s["frf"]["noise_total"] is not None                     # the spread over the realisations


def test_realisations_that_each_ramp_in_are_counted_once():
    """Three realisations, each ramping into its multisine over 2 s of a 5.12 s period (as
    mocapfj.synth's references do): the ramp's period is the realisation's transient, not a fourth
    realisation; one ramped realisation alone is one."""
    from mocapfj.ident.multisine import multisine_realisations
    from mocapfj.pipeline.frf import find_period_and_realisations

    ms = design_multisine(200.0, 1024, 0.5, 20.0, rms=0.01, seed=2)
    t = np.arange(4 * 1024) / 200.0
    parts = [0.3 + np.clip(t / 2.0, 0, 1) * (m.amplitudes * np.cos(2 * np.pi * np.outer(t, m.lines * 200.0 / 1024)
                                                                     + m.phases)).sum(axis=1)
             for m in multisine_realisations(ms, 3, seed=9)]
    assert find_period_and_realisations(np.concatenate(parts), exact=True) == (1024, 3)
    assert find_period_and_realisations(parts[0], exact=True) == (1024, 1)
