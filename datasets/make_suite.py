"""Write the concealed-effect suite: datasets/suite/<effect>_{ident,valid}.toml and control_*.

Every scenario is pa10_joint2 (Lightcap and Banks (2007), Table I, joint 2) with one effect of the discovery
vocabulary planted in the true system, sized so that its contribution to the measured deflection
has an RMS below the per-sample noise SD of that deflection (0.43 mrad: 0.2 mm marker noise on
the four link markers). The identification and the validation trial share the effect and differ
in seed and excitation. `mocapfj simulate` reports each effect's RMS / noise ratio; the suite's
measured ratios are listed in datasets/README.md.

Run from the repository root: ``python datasets/make_suite.py``. The files it writes are
committed; edit this script, not them.
"""

from __future__ import annotations

import copy
import tomllib
from pathlib import Path

import tomli_w

HERE = Path(__file__).resolve().parent
SUITE = HERE / "suite"

# effect -> (planted parameters, one-line physical description)
EFFECTS = {
    "hysteresis": ({"spring": {"model": "bouc_wen", "k": 1.19e4, "alpha": 0.93, "beta": 300.0, "gamma": 300.0}},
                   "Bouc-Wen flexspline hysteresis: 7 % of the stiffness hysteretic, loop half-width 1.7 mrad"),
    "stiffening": ({"spring": {"model": "piecewise", "k1": 0.95e4, "k2": 1.15e4, "k3": 1.25e4, "tau1": 8.0, "tau2": 35.0}},
                   "harmonic-drive soft wind-up: K1 < K2 < K3 with breaks at 8 and 35 N m"),
    "backlash": ({"gap_rad": 5.0e-4}, "0.5 mrad lost motion (dead zone) around zero spring torque"),
    "transmission_error": ({"amplitudes_rad": [2.5e-4, 1.2e-4], "phases_rad": [0.4, 1.7], "orders": [1.0, 2.0]},
                           "kinematic error at 1x and 2x the wave-generator turn, 0.25 and 0.12 mrad"),
    "position_dependent_friction": ({"amplitudes_Nm": [3.0, 1.5], "phases_rad": [0.3, 1.2], "orders": [8.0, 16.0]},
                                    "Coulomb level ripples by 3 and 1.5 N m at 8 and 16 cycles per link turn"),
    "stribeck": ({"friction": {"model": "stribeck", "fc": 9.28, "fs": 15.0, "vs": 0.02, "fv": 18.38}},
                 "breakaway friction 15 N m falling to 9.28 N m Coulomb within 0.02 rad/s"),
    "friction_asymmetry": ({"friction": {"model": "asymmetric_coulomb_viscous", "c_pos": 11.0, "v_pos": 19.5,
                                         "c_neg": 7.6, "v_neg": 17.2}},
                           "Coulomb 11.0 / 7.6 N m and viscous 19.5 / 17.2 N m s for positive / negative speed"),
    "time_delay": ({"delay_s": 1.0e-3}, "mocap clock 1.0 ms late beyond the declared offset"),
    "coupling": ({"source": "j3", "inertia_kgm2": 2.5}, "reaction torque -2.5 kg m^2 x q3'' from the moving elbow"),
    "gravity_mismatch": ({"k": 5000.0, "a": 0.10, "b": 0.30, "free_length": 0.20, "q0": 0.0},
                         "a spring gravity balancer, 5 kN/m on 0.10 / 0.30 m arms, free length 0.20 m"),
    "drive_gain": ({"gain": 1.05}, "the drive delivers 5 % more torque than the controller logs"),
}

# identification and validation excitations (Lightcap and Banks (2007), eq. 9) and seeds
TRIALS = {
    "ident": {"seed": 100, "reference": {"f0_hz": 0.1, "q0_rad": 0.3, "amplitudes_rad": [0.30, 0.12, 0.08, 0.05, 0.03],
                                         "phases_rad": [0.0, 1.1, 2.3, 0.7, 1.9], "ramp_s": 2.0}},
    "valid": {"seed": 200, "reference": {"f0_hz": 0.125, "q0_rad": 0.2, "amplitudes_rad": [0.25, 0.15, 0.06, 0.06, 0.02],
                                         "phases_rad": [0.9, 2.4, 0.3, 1.5, 2.8], "ramp_s": 2.0}},
}

J3 = {  # the neighbour that moves in the coupling scenarios: Lightcap and Banks (2007), Table I joint 3
    "name": "j3", "axis": 3, "gear_ratio": 50.0, "I": 2.27, "J": 2.48, "mglx": 8.33, "mgly": 8.56, "b": 6.35,
    "link_markers": ["L3_1", "L3_2", "L3_3"], "parent_markers": ["L2_1", "L2_2", "L2_3", "L2_4"],
    "friction": {"model": "coulomb_viscous", "c": 5.81, "v": 5.79}, "spring": {"model": "linear", "k": 4.60e3},
    "control": {"kp": 8.0e3, "kd": 250.0},
    "reference": {"f0_hz": 0.1, "q0_rad": -0.3, "amplitudes_rad": [0.0, 0.0, 0.08, 0.06, 0.05],
                  "phases_rad": [0.0, 0.0, 0.5, 1.9, 2.7], "ramp_s": 2.0},
}


def scenario(effect: str | None, trial: str) -> dict:
    base = tomllib.loads((HERE / "pa10_joint2.toml").read_text())
    doc = copy.deepcopy(base)
    label = effect or "control"
    doc["name"] = f"{label}_{trial}"
    doc["seed"] = TRIALS[trial]["seed"] + (sorted(EFFECTS).index(effect) + 1 if effect else 0)
    doc["joints"][0]["reference"] = copy.deepcopy(TRIALS[trial]["reference"])
    if effect is None:
        doc["description"] = f"concealed-effect suite, {trial} trial: no effect (control)"
        return doc
    params, what = EFFECTS[effect]
    doc["description"] = f"concealed-effect suite, {trial} trial: {what}"
    if effect == "coupling":
        doc["joints"].append(copy.deepcopy(J3))
    doc["effects"] = [{"name": effect, "joint": "j2", **copy.deepcopy(params)}]
    return doc


def _write(docs, out: Path) -> list[Path]:
    """Write scenario documents into `out` with the generated-file header."""
    out.mkdir(exist_ok=True)
    head = "# Generated by datasets/make_suite.py: edit that script, not this file.\n"
    written = []
    for doc in docs:
        path = out / f"{doc['name']}.toml"
        path.write_text(head + tomli_w.dumps(doc))
        written.append(path)
    print(f"wrote {len(written)} scenarios to {out}")
    return written


def main(out: Path = SUITE) -> list[Path]:
    return _write((scenario(effect, trial) for effect in list(EFFECTS) + [None] for trial in TRIALS), out)


# two effects planted together (discovery must find both): one in the spring, one in the friction
COMBINED = {"two_effects": ("hysteresis", "friction_asymmetry")}


def combined_scenario(label: str, trial: str) -> dict:
    effects = COMBINED[label]
    doc = scenario(effects[0], trial)
    doc["name"] = f"{label}_{trial}"
    doc["seed"] = TRIALS[trial]["seed"] + 50
    doc["description"] = f"discovery, {trial} trial: " + "; ".join(EFFECTS[e][1] for e in effects)
    doc["effects"] = [{"name": e, "joint": "j2", **copy.deepcopy(EFFECTS[e][0])} for e in effects]
    return doc


def combined(out: Path = HERE / "discovery") -> list[Path]:
    """Scenarios with several effects at once, beside the one-effect suite."""
    return _write((combined_scenario(label, trial) for label in COMBINED for trial in TRIALS), out)


if __name__ == "__main__":
    main()
    combined()
