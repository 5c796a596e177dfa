"""mocapfj identify: two repeated pa10_joint2 trials through the whole chain."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from mocapfj.cli import main
from mocapfj.synth.record import record_scenario, write_scenario_bundle
from mocapfj.synth.scenario import load_scenario

DATASETS = Path(__file__).resolve().parents[2] / "datasets"
TABLE1_J2 = {"I": 6.15, "mglx": 111.64, "mgly": -7.80, "c": 9.28, "v": 18.38, "J": 12.57, "b": 23.28, "k": 1.19e4}


@pytest.fixture(scope="module")
def two_trials(tmp_path_factory):
    root = tmp_path_factory.mktemp("identify")
    scn = load_scenario(DATASETS / "pa10_joint2.toml").with_duration(20.0)
    paths = []
    for seed in (11, 12):
        write_scenario_bundle(record_scenario(replace(scn, seed=seed), with_concealment=False), root / f"t{seed}")
        paths.append(root / f"t{seed}")
    return root, paths


def test_identify_json_table_and_cv(two_trials, capsys):
    root, paths = two_trials
    assert main(["identify", *map(str, paths), "--out", str(root / "out"), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    (j,) = s["joints"]
    assert j["name"] == "j2" and j["n_trials"] == 2
    assert set(j["params"]) == set(TABLE1_J2) and {"value", "std", "rel_std_pct"} <= set(j["params"]["I"])
    assert {"cond_two_step", "cond_one_step", "torque_rms", "spring", "cv_pct"} <= set(j)
    assert {"model", "params", "r2"} <= set(j["spring"])
    assert j["cond_two_step"] < j["cond_one_step"]  # seed 000's argument for the two-step method
    # what the mocap chain identifies well (see test_twostep for the link/motor split it does not)
    for n in ("mglx", "mgly", "c"):
        assert j["params"][n]["value"] == pytest.approx(TABLE1_J2[n], rel=0.02), n
    assert j["k_one_step"] == pytest.approx(TABLE1_J2["k"], rel=0.02)
    assert (root / "out" / "table.md").read_text().count("| j2 |") == 2
    assert (root / "out" / "table.csv").read_text().splitlines()[0] == "joint,statistic,I,c,v,mglx,mgly,b,J,k,error"
