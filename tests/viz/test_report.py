"""The report (mocapfj.viz.report, mocapfj report): the HTML parses, every figure is a decodable,
non-blank PNG, the numbers printed are those of the JSON results, parameters not determined say
so with the reason, stages that did not run are listed, one command's --out works alone, bad
input is one line naming the file (exit 2), and the inputs are left as they were.

The run directory is written here in the documented formats (docs/formats.md) from a joint with
known parameters: a linear spring k = 5000 N m/rad, tau0 = -3 N m, J = 2 kg m^2, b = 1.5 N m s/rad,
so the spring figure's fit must pass through the spring torque the motor equation gives.
"""

from __future__ import annotations

import base64
import hashlib
import html.parser
import io
import json
import math
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mocapfj.errors import InputError
from mocapfj.io import write_json, write_recording
from mocapfj.io.csvio import write_csv_columns
from mocapfj.synth import toy_recording
from mocapfj.viz.report import build_report
from mocapfj.viz.report_format import parse_pm, pm

ROOT = Path(__file__).resolve().parents[2]
K, TAU0, J, B = 5000.0, -3.0, 2.0, 1.5
I_REASON = "relative SD 9.1 %: only I + J = 3.1 +- 0.02 is determined; a faster motion would determine it"
PARAMS = {"I": (1.1, 0.1, False), "mglx": (12.345678, 0.0123, True), "c": (0.8123, 0.0042, True),
          "v": (0.5, 0.011, True), "J": (J, 0.02, True), "b": (B, 0.031, True), "k": (5012.3456, 37.21, True)}


def _joint_files(d: Path, rng) -> None:
    d.mkdir(parents=True, exist_ok=True)
    fs, T = 250.0, 20.0
    t = np.arange(int(T * fs) + 1) / fs
    q_m = 0.3 * np.sin(2 * np.pi * 0.5 * t) + 0.1 * np.sin(2 * np.pi * 1.3 * t)
    qd = 0.3 * 2 * np.pi * 0.5 * np.cos(2 * np.pi * 0.5 * t) + 0.1 * 2 * np.pi * 1.3 * np.cos(2 * np.pi * 1.3 * t)
    qdd = -0.3 * (2 * np.pi * 0.5) ** 2 * np.sin(2 * np.pi * 0.5 * t) - 0.1 * (2 * np.pi * 1.3) ** 2 * np.sin(
        2 * np.pi * 1.3 * t)
    delta = 2e-3 * np.sin(2 * np.pi * 0.5 * t + 0.4)
    tau = J * qdd + B * qd + K * delta + TAU0
    sd = 1e-4
    meas = delta + sd * rng.standard_normal(t.size)
    write_csv_columns(d / "j1.angles.csv", {
        "t_mocap": t, "t_controller": t, "q": q_m - meas, "sigma_q": np.full(t.size, sd), "q_m": q_m, "delta": meas,
        "sigma_delta": np.full(t.size, sd), "tau": tau, "n_markers": np.full(t.size, 4.0),
        "n_rejected": np.zeros(t.size), "marker_rms": np.full(t.size, 2e-4)})
    (d / "j1.joint.toml").write_text(
        'format = "mocapfj.joint/1"\njoint = "j1"\nmethod = "ml"\nn_frames = 5001\naxis = [0.0, 1.0, 0.0]\n'
        "point_m = [0.01, 0.02, 0.03]\nsigma_m = 0.0002\nmarker_rms_m = 0.00033\n"
        "cov_axis = [[4e-8, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1e-8]]\n"
        "cov_point_m2 = [[9e-8, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 4e-8]]\n")
    write_json(d / "joints.json", {"recording": "toy", "method": "auto", "joints": [{
        "name": "j1", "axis": [0.0, 1.0, 0.0], "point_m": [0.01, 0.02, 0.03], "axis_world": [0.0, 1.0, 0.0],
        "point_world_m": [0.01, 0.02, 0.93], "radii_mm": [100.0, 150.0, 200.0, 250.0],
        "radius_rms_mm": [0.2, 0.2, 0.2, 0.2], "marker_rms_mm": 0.33, "angle_marker_rms_mm": 0.33,
        "fit_marker_rms_mm": 0.331, "angle_sigma_rad": 1e-4, "n_frames": 5001, "n_frames_invalid": 0, "method": "ml",
        "q_range_deg": 45.0, "q_offset_rad": 0.01, "deflection_rms_rad": 1.4e-3, "parent_static": True,
        "files": {"geometry": "j1.joint.toml", "angles": "j1.angles.csv"}}]})


def _identify(d: Path) -> None:
    d.mkdir(parents=True, exist_ok=True)
    params = {n: {"value": v, "std": s, "rel_std_pct": 100 * s / abs(v), "determined": det}
              for n, (v, s, det) in PARAMS.items()}
    params["I"]["reason"] = I_REASON
    write_json(d / "identify.json", {"recordings": ["toy"], "joints": [{
        "name": "j1", "method": "output_error", "params": params, "cond_two_step": 40.0, "torque_rms": 0.05,
        "spring": {"model": "linear", "params": {"k": K, "tau0": TAU0}, "r2": 0.9999, "n_trials_chosen": 1},
        "n_trials": 1, "combinations": {"I+J": {"value": 3.1, "std": 0.02}}, "band_hz": 4.0,
        "residual_sd": {"q_rad": 1e-4, "u_Nm": 0.05},
        "clock_offset": {"offset_s": 0.0, "sd_s": 0.001, "applied": False},
        "not_determined": {"I": I_REASON}}]})
    (d / "table.md").write_text("| joint |\n|---|\n| j1 |\n")


def _discover(d: Path) -> None:
    d.mkdir(parents=True, exist_ok=True)
    fits = {"fit": 97.0, "floor": 98.0, "floor_sd": 0.06, "band_hz": 4.0}
    write_json(d / "discovery.json", {
        "recording": "toy", "model": "identified",
        "effects": [{"name": "hysteresis", "joint": "j1", "explanation": "The spring torque lags at each reversal.",
                     "location": {"signal": "spring torque vs deflection", "where": "deflection reversals",
                                  "residual": "spring",
                                  "held_out": {"validation recording": {"gain_points": 0.1324, "sd_points": 0.0232}},
                                  "candidates": [{"name": "hysteresis", "held_out_gain_points": 0.26,
                                                  "held_out_gain_sd_points": 0.05, "admissible": True}]},
                     "parameters": {"k": 5010.0, "alpha": 0.98}, "p_value": 4.8e-6, "fit_gain_pct": 0.07}],
        "fits": {"j1": {"before": fits, "after": dict(fits, fit=97.5)}},
        "validation": {"fits": {"j1": {"before": dict(fits, fit=96.0), "after": dict(fits, fit=96.4)}},
                       "effects": [{"name": "hysteresis", "joint": "j1", "fit_gain_pct": 0.1031}]},
        "location": {"j1": {"spring": {"worst_windows": [{"t_start_s": 4.0, "t_end_s": 6.0}]}}},
        "rejected": [{"name": "backlash", "joint": "j1", "reason": "it lowers the held-out fit"}],
        "verdict": "missing physics: hysteresis (j1)", "stopped": "no further effect is significant"})
    t = np.arange(5001) / 250.0
    r = 1e-4 * np.sin(2 * np.pi * 0.5 * t)
    write_csv_columns(d / "residuals.csv", {"t": t, "j1_r_delta_before": r + 5e-5 * np.sign(np.cos(np.pi * t)),
                                           "j1_r_delta_after": r, "j1_r_u_before": 10 * r, "j1_r_u_after": 8 * r})


def _frf(d: Path) -> dict:
    from mocapfj.ident.frf_fit import two_inertia_frf

    d.mkdir(parents=True, exist_ok=True)
    p = dict(J=0.75, I=1.165, k=1150.0, d=1.0, b=0.8, v=0.3)
    f = np.linspace(0.8, 12.0, 30)
    g = two_inertia_frf(f, **p)
    meas = g * (1 + 0.01 * np.cos(7 * f))
    write_csv_columns(d / "frf.csv", {"f_hz": f, "G_real": meas.real, "G_imag": meas.imag, "magnitude": np.abs(meas),
                                      "phase_rad": np.unwrap(np.angle(meas)), "coherence": np.full(f.size, 0.99),
                                      "noise": 0.01 * np.abs(meas), "model_real": g.real, "model_imag": g.imag})
    model = {"name": "two_inertia", "output": "motor",
             "params": {n: {"value": v, "std": 0.003 * v, "rel_std_pct": 0.3} for n, v in p.items()},
             "chi2": 30.0, "dof": 54, "chi2_red": 0.56, "modes": []}
    out = {"file": "ms.csv", "input": "u", "output": "q_m", "reference": "r", "fs_hz": 333.3, "period_s": 6.144,
           "period_samples": 2048, "transient_periods": 1,
           "frf": {"estimator": "indirect", "closed_loop": True, "n_periods": 4, "n_realisations": 1,
                   "frequencies_hz": f.tolist(), "coherence": [0.99] * f.size, "distortion": {}},
           "model": model, "modes": [{"kind": "antiresonance", "f_hz": 5.0005, "zeta": 0.0178, "f_hz_std": 0.001,
                                      "zeta_std": 0.0002}],
           "files": {"summary": "frf.json", "frf": "frf.csv"}}
    from mocapfj.pipeline.frf import compare_with_identify

    ident = {n: {"value": v * (1.08 if n == "k" else 1.0), "std": 0.005 * v, "determined": n != "I",
                 "reason": "only I + J is determined"} for n, v in p.items()}
    out["comparison"] = compare_with_identify(out, "j1", ident, "identify.json")
    write_json(d / "frf.json", out)
    return out


def _stage(name, status, **kw):
    return {"name": name, "status": status, "inputs_sha256": None, "dir": name, "files": [], "seconds": 1.0,
            "error": None, **kw}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    d = tmp_path_factory.mktemp("run")
    rec = d.parent / (d.name + "_rec")
    write_recording(toy_recording(duration_s=2.0), rec)
    rng = np.random.default_rng(5)
    _joint_files(d / "joints", rng)
    _identify(d / "identify")
    _discover(d / "discover")
    shutil.copytree(d / "joints", d / "discover" / "joints")
    frf = _frf(d / "frf")
    write_json(d / "run.json", {"format": "mocapfj.run/1", "recording": str(rec), "validation": None,
                                "created_utc": "2026-01-01T00:00:00Z", "mocapfj_version": "test", "stages": [
                                    _stage("calibrate_rig", "failed", error="the wand file has 2 markers"),
                                    _stage("triangulate", "not_applicable", reason="the bundle has 3D markers"),
                                    _stage("joints", "done"), _stage("identify", "done"), _stage("discover", "done"),
                                    _stage("frf", "done")]})
    before = _digest(d)
    result = build_report(d)
    return d, result, before, frf


def _digest(d: Path) -> dict:
    return {str(p.relative_to(d)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(d.rglob("*"))
            if p.is_file() and not p.name.startswith("report") and "report_files" not in p.parts}


class _Parsed(html.parser.HTMLParser):
    def __init__(self):
        super().__init__()
        self.imgs, self.rows, self.ids, self._row, self._cell = [], [], set(), None, None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if "id" in a:
            self.ids.add(a["id"])
        if tag == "img":
            self.imgs.append(a)
        elif tag == "tr":
            self._row = []
        elif tag in ("td", "th") and self._row is not None:
            self._cell = []

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self._row.append("".join(self._cell).strip())
            self._cell = None
        elif tag == "tr" and self._row is not None:
            self.rows.append(self._row)
            self._row = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)


def _parse(path: Path) -> _Parsed:
    p = _Parsed()
    p.feed(path.read_text(encoding="utf-8"))
    p.close()
    return p


def _decode_png(data: bytes) -> np.ndarray:
    import matplotlib.image

    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return matplotlib.image.imread(io.BytesIO(data), format="png")


def _not_blank(img: np.ndarray) -> None:
    rgb = img[..., :3].reshape(-1, 3)
    assert rgb.std() > 0.05, rgb.std()
    c = (rgb * 255).round().astype(np.int64)
    assert np.unique(c[:, 0] << 16 | c[:, 1] << 8 | c[:, 2]).size > 20       # more than a colour or two


def _row(p: _Parsed, first: str, after: str | None = None) -> list[str]:
    rows = [r for r in p.rows if r and r[0] == first]
    assert rows, f"no table row {first!r}"
    return rows[0]


def test_html_parses_and_every_figure_is_a_png_that_is_not_blank(run):
    d, result, _, _ = run
    assert result.html == d.resolve() / "report.html" and result.markdown.is_file()
    p = _parse(result.html)
    assert {"stages", "recording", "joints", "identification", "spring", "frf", "discovery"} <= p.ids
    assert set(result.sections) >= {"stages", "recording", "joints", "identification", "spring", "frf", "discovery"}
    names = [a["data-name"] for a in p.imgs]
    assert names == list(result.figures) and len(names) >= 5          # signals, SD bars, spring, FRF, residuals
    for a in p.imgs:
        head, data = a["src"].split(",", 1)
        assert head == "data:image/png;base64"                        # embedded: the file stands alone
        png = base64.b64decode(data)
        _not_blank(_decode_png(png))
        assert (d / "report_files" / a["data-name"]).read_bytes() == png
    md = result.markdown.read_text()
    for n in names:
        assert f"(report_files/{n})" in md
    assert "<script" not in result.html.read_text()
    assert not list(d.glob(".report*"))                               # no staging left behind


def test_numbers_printed_are_the_json_values(run):
    d, result, _, frf = run
    p = _parse(result.html)
    ident = json.loads((d / "identify" / "identify.json").read_text())["joints"][0]["params"]
    for name in ("k", "mglx", "c", "J"):
        row = _row(p, name)
        v, s, half = parse_pm(row[2])
        assert abs(v - ident[name]["value"]) <= half * 1.0001, (row, ident[name])
        assert abs(s - ident[name]["std"]) <= max(half, 0.05 * ident[name]["std"]), (row, ident[name])
    assert _row(p, "k")[2] == "5012 ± 37" and _row(p, "mglx")[2] == "12.346 ± 0.012"
    # the FRF's fitted stiffness (its table: parameter, meaning, value ± SD, unit)
    krow = [r for r in p.rows if len(r) == 4 and r[0] == "k" and r[1] == "joint stiffness"][-1]
    v, s, half = parse_pm(krow[2])
    assert abs(v - frf["model"]["params"]["k"]["value"]) <= half * 1.0001
    # the held-out gain of the effect on the validation recording, as in discovery.json
    row = _row(p, "held-out gain (validation recording)")
    assert parse_pm(row[1])[:2] == (0.132, 0.023)
    assert _row(p, "fit gain on the validation recording")[1] == "0.103 points"      # 0.1031 to 3 digits


def test_not_determined_parameters_say_so_with_the_reason(run):
    _, result, _, _ = run
    p = _parse(result.html)
    row = _row(p, "I")
    assert row[-1] == "not determined"
    assert all(r[-1] == "yes" for r in p.rows if len(r) == 6 and r[0] in ("k", "J", "mglx"))
    text = result.html.read_text()
    assert "I (link inertia) is not determined: " + I_REASON.replace("+", "+") in text
    assert I_REASON in result.markdown.read_text()


def test_stages_that_did_not_run_are_listed_with_their_reason(run):
    _, result, _, _ = run
    missing = dict(result.stages_missing)
    assert set(missing) == {"calibrate_rig", "triangulate"}
    assert "failed" in missing["calibrate_rig"] and "2 markers" in missing["calibrate_rig"]
    assert "3D markers" in missing["triangulate"]
    assert "calibration" not in result.sections
    assert "Stages that did not run" in result.markdown.read_text()


def test_spring_fit_passes_through_the_motor_equations_spring_torque(run):
    """The section recomputes tau_s = u - J q_m'' - b q_m' from the angles file: with the known J, b
    the points lie on the known line, so what the line leaves is the deflection noise x k alone."""
    from mocapfj.io.csvio import read_csv_columns
    from mocapfj.viz.figures import smooth_derivatives

    d, _, _, _ = run
    a = read_csv_columns(d / "joints" / "j1.angles.csv")
    qd, qdd = smooth_derivatives(a["q_m"], 1 / 250.0)
    tau_s = a["tau"] - J * qdd - B * qd
    res = tau_s - (TAU0 + K * a["delta"])
    inner = slice(20, -20)
    assert abs(np.std(res[inner]) / (K * 1e-4) - 1) < 0.05                # the 1e-4 rad noise x k
    assert abs(np.mean(res[inner])) < 0.05


def test_inputs_are_not_modified_and_a_rebuild_replaces_the_outputs(run, tmp_path):
    d, result, before, _ = run
    assert _digest(d) == before
    small = tmp_path / "frf"
    shutil.copytree(d / "frf", small)
    (small / "report_files").mkdir()
    (small / "report_files" / "stale.png").write_bytes(b"old")         # a figure no longer made goes
    first = build_report(small)
    html = first.html.read_bytes()
    again = build_report(small)
    assert again.figures == first.figures == ("frf.png",) and again.html.read_bytes() == html   # deterministic
    assert sorted(p.name for p in (small / "report_files").iterdir()) == ["frf.png"]
    assert not list(small.glob(".report*"))


def test_one_commands_out_alone(run, tmp_path):
    d = run[0]
    shutil.copytree(d / "discover", tmp_path / "disc")
    r = build_report(tmp_path / "disc")
    assert "discovery" in r.sections and "joints" in r.sections and "identification" not in r.sections
    assert "identify" in dict(r.stages_missing) and "recording" not in r.sections
    shutil.copytree(d / "identify", tmp_path / "ident")
    r = build_report(tmp_path / "ident")
    assert r.sections == ("stages", "identification")       # no angles beside identify.json: no spring figure


def test_bad_input_names_the_file(run, tmp_path):
    with pytest.raises(InputError, match="no such directory"):
        build_report(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="none of them"):
        build_report(tmp_path / "empty")
    bad = tmp_path / "bad"
    shutil.copytree(run[0] / "identify", bad)
    (bad / "identify.json").write_text('{"recordings": [], "joints": [{"name": "j1", "params": {"k": 3}}]}')
    with pytest.raises(InputError, match=re.escape(str(bad / "identify.json"))):
        build_report(bad)


def test_pm_rounds_at_the_sds_second_digit():
    assert pm(11165.928, 79.133) == "11166 ± 79"
    assert pm(5.3299, 0.35689) == "5.33 ± 0.36"
    assert pm(-7.818451, 0.0040386) == "-7.8185 ± 0.0040"
    assert pm(1234567.0, 12345.0) == "(1.235 ± 0.012)e+06"
    assert pm(3.0e-5, 1.0e-7, "rad") == "(3.000 ± 0.010)e-05 rad"
    for v, s in ((11165.928, 79.133), (-7.818451, 0.0040386), (1234567.0, 12345.0), (3e-5, 1e-7)):
        pv, ps, half = parse_pm(pm(v, s))
        assert abs(pv - v) <= half * 1.0001 and math.isclose(ps, s, rel_tol=0.05)


def test_cli_report_subprocess(run, tmp_path):
    d = tmp_path / "r"
    shutil.copytree(run[0] / "identify", d)
    r = subprocess.run([sys.executable, "-m", "mocapfj.cli", "report", str(d), "--json"], capture_output=True,
                       text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["sections"] == ["stages", "identification"] and s["figures"] == ["identify_j1_sd.png"]
    assert Path(s["html"]).is_file() and {m["name"] for m in s["stages_missing"]} >= {"joints", "discover"}
    (d / "identify.json").write_text("{not json")
    r = subprocess.run([sys.executable, "-m", "mocapfj.cli", "report", str(d)], capture_output=True, text=True,
                       cwd=ROOT, timeout=120)
    assert r.returncode == 2 and r.stdout == "" and r.stderr.count("\n") == 1
    assert str(d / "identify.json") in r.stderr and "Traceback" not in r.stderr


def test_a_disagreement_with_the_time_domain_identification_is_said(run):
    d, result, _, frf = run
    text = result.html.read_text()
    p = _parse(result.html)
    assert "frf and identify disagree on k" in text
    rows = {r[0]: r for r in p.rows if len(r) == 7}                   # the comparison's table
    assert rows["k"][-1] == "disagree" and rows["k"][1] == "N m/rad"
    assert float(rows["k"][4]) == pytest.approx(frf["comparison"]["params"][0]["diff_pct"], rel=1e-2)
    assert rows["J"][-1] == "agree" and rows["I"][-1].startswith("identify did not determine it: only I + J")
