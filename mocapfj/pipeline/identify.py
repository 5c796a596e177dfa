"""Composition of identification: one joint's signals (`identify_signals`), a recording
(`identify_recording`: every joint alone, or the links of a URDF together), repeated recordings
with CV % and the Table-I-style tables (`run_identify`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import load_recording, write_json
from ..types import Recording
from .core import STEP1, joint_signals, run_joints

IDENTIFY_METHODS = ("motor_first", "seed")


def _spring_pairs(delta, tau_s, t, fs_hz: float, cutoff_hz: float = 10.0, rate_hz: float = 50.0):
    """(delta, tau_s, t) for spring selection: both low-passed at `cutoff_hz` (mocap noise in
    delta would otherwise hide a 10 % nonlinearity) and kept at `rate_hz` (nearly independent
    samples; the hysteresis fits are 5x cheaper)."""
    from ..ident.conditioning import lowpass

    stride = max(1, int(round(fs_hz / rate_hz)))
    return lowpass(delta, fs_hz, cutoff_hz)[::stride], lowpass(tau_s, fs_hz, cutoff_hz)[::stride], t[::stride]


def identify_signals(t, q, q_m, u, fs_hz: float, method: str = "motor_first", cutoff_hz: float | None = None,
                     decimate: int = 2, spring_models=None) -> dict:
    """Identify one joint from its signals on one clock (t, q, q_m, u: s, rad, rad, N m, link side).

    Both formulations run: seed 000's two-step (eq. 5-7) and one-step (eq. 4) give the condition
    numbers seed 000 compares and the one-step k; `method` chooses whose parameters are reported:
    "motor_first" (default, :mod:`mocapfj.ident.motorfirst`, the one that resolves the link/motor
    split through mocap) or "seed" (step 1 of eq. 6 with the spring of eq. 7). The spring model is
    then selected by held-out error among `spring_models` (default all) on that method's
    (deflection, spring torque) pairs. `cutoff_hz` is the seed method's low-pass (default 10 Hz);
    motor-first uses its documented defaults. Returns a dict (see `run_identify`).
    """
    from ..ident.motorfirst import identify_joint_motor_first
    from ..ident.springs import HYSTERETIC, SPRING_FITTERS, select_spring_model
    from ..ident.twostep import identify_joint

    if method not in IDENTIFY_METHODS:
        raise InputError(None, "method", f"one of {list(IDENTIFY_METHODS)}", repr(method))
    seed = identify_joint(t, q, q_m, u, fs_hz=fs_hz, cutoff_hz=10.0 if cutoff_hz is None else cutoff_hz,
                          decimate=decimate)
    out = {"method": method, "cond_two_step": seed.cond_two_step, "cond_one_step": seed.cond_one_step,
           "k_one_step": seed.one_step["k"], "seed_step1": seed.step1}
    models = tuple(spring_models or SPRING_FITTERS)
    if method == "seed":
        values = {n: (seed.step1[n], seed.step1.std[i]) for i, n in enumerate(STEP1)}
        values["k"] = (seed.spring["k"], seed.spring.std[0])
        out.update(torque_rms=seed.torque_rms, q_zero_rad=seed.q_zero_rad)
        ts, tau_s, delta = seed.t, seed.tau_s, seed.delta
        spring = select_spring_model(delta, tau_s, ts, models=models)
    else:
        # a linear pass (which also tests the motor equation for a hysteretic spring); without
        # hysteresis the spring model is selected on its pairs and, when it is not linear, the motor
        # equation is solved again with that shape and the spring refitted on the new pairs
        mf = identify_joint_motor_first(t, q, q_m, u, fs_hz=fs_hz, decimate=decimate)
        if mf.hysteresis is not None:
            spring = _hysteretic_spring(mf, fs_hz)
        else:
            spring = select_spring_model(*_spring_pairs(mf.delta, mf.tau_s, mf.t, fs_hz), models=tuple(m for m in models if m not in HYSTERETIC))
            if spring.chosen.model != "linear":
                mf = identify_joint_motor_first(t, q, q_m, u, fs_hz=fs_hz, decimate=decimate,
                                                spring=spring.chosen.predict, q_zero_rad=mf.q_zero_rad)
                spring = select_spring_model(*_spring_pairs(mf.delta, mf.tau_s, mf.t, fs_hz), models=(spring.chosen.model, "linear"))
        values = {}
        for n in (*STEP1, "k"):
            part = mf.link if n in mf.link.names else mf.motor
            values[n] = (part[n], float(part.std[part.names.index(n)]))
        out.update(torque_rms=mf.motor.residual_rms, q_zero_rad=mf.q_zero_rad, cond_motor=mf.motor.cond,
                   cond_link=mf.link.cond)
    out["values"] = values
    out["spring"] = spring if isinstance(spring, dict) else {
        "model": spring.chosen.model, "params": {k: float(v) for k, v in spring.chosen.params.items()},
        "r2": spring.r2, "holdout_rms_Nm": spring.holdout_rms}
    return out


def _hysteretic_spring(mf, fs_hz: float) -> dict:
    """The Bouc-Wen spring the motor equation found, with its r2 on the spring pairs."""
    from ..ident.springs import bouc_wen_states

    h = mf.hysteresis
    d, tau, _ = _spring_pairs(mf.delta, mf.tau_s, mf.t, fs_hz)
    pred = h["alpha"] * h["k"] * d + (1 - h["alpha"]) * h["k"] * bouc_wen_states(d, 1.0, h["beta"], h["gamma"])
    r = tau - pred
    r -= r.mean()                                             # the torque offset
    dev = tau - tau.mean()
    return {"model": "bouc_wen", "params": {n: h[n] for n in ("k", "alpha", "beta", "gamma")},
            "r2": float(1 - (r @ r) / (dev @ dev)), "motor_rms_gain_pct": h["rms_gain_pct"]}


def _urdf_chain(rec: Recording) -> bool:
    """True when the recording has a URDF whose joints are exactly its joints, in order, and more
    than one: then the links are identified together (`mocapfj.ident.nlink`)."""
    if rec.urdf is None or len(rec.joints) < 2:
        return False
    from ..ident.regressor import load_pin_model

    return tuple(load_pin_model(rec.urdf).names[1:]) == tuple(j.name for j in rec.joints)


def _identify_nlink(rec: Recording, out: Path, decimate: int) -> list[dict]:
    """Motor equations per joint, then the links' base parameters through the URDF."""
    from ..ident.nlink import identify_nlink_motor_first
    from ..ident.springs import HYSTERETIC, SPRING_FITTERS, select_spring_model

    sig = [joint_signals(rec, out / "joints" / f"{spec.name}.angles.csv", i) for i, spec in enumerate(rec.joints)]
    n = min(s[0].size for s in sig)
    t = sig[0][0][:n]
    Q, Q_m, U = (np.column_stack([s[k][:n] for s in sig]) for k in (1, 2, 3))
    fs = rec.markers.rate_hz
    try:
        res = identify_nlink_motor_first(rec.urdf, t, Q, Q_m, U, fs_hz=fs, decimate=decimate)
    except InputError as e:
        raise InputError(rec.root, f"n-link identification ({e.field})", e.expected, e.got, e.hint) from None
    base = {name: (float(v), float(sd)) for name, v, sd in zip(res.base.names, res.base.values, res.base.std)}
    results = []
    for spec, m, s in zip(rec.joints, res.motors, sig):
        if m.hysteresis is not None:
            spring = {"model": "bouc_wen", "params": {k: m.hysteresis[k] for k in ("k", "alpha", "beta", "gamma")},
                      "motor_rms_gain_pct": m.hysteresis["rms_gain_pct"]}
        else:
            inner = m.inner
            sel = select_spring_model(*_spring_pairs(m.delta[inner], m.tau_s[inner], m.t[inner], fs),
                                      models=tuple(k for k in SPRING_FITTERS if k not in HYSTERETIC))
            spring = {"model": sel.chosen.model, "params": {k: float(v) for k, v in sel.chosen.params.items()},
                      "r2": sel.r2, "holdout_rms_Nm": sel.holdout_rms}
        results.append({
            "name": spec.name, "recording": rec.name, "frames_filled": s[4], "method": "nlink_motor_first",
            "values": {n_: (m.motor[n_], float(m.motor.std[m.motor.names.index(n_)])) for n_ in ("J", "b", "k")},
            "torque_rms": m.motor.residual_rms, "cond_motor": m.motor.cond, "q_zero_rad": m.q_zero_rad,
            "spring": spring, "nlink": {"base": base, "cond": res.base.cond, "torque_rms": res.base.residual_rms,
                                        "r2": res.base.r2},
        })
    return results


def identify_recording(recording: str | Path, out: str | Path, method: str = "motor_first",
                       cutoff_hz: float | None = None, decimate: int = 2) -> list[dict]:
    """Identify every joint of one recording.

    Runs `run_joints` into OUT/joints and puts the link angle and the controller log on the mocap
    samples (controller clock, `joint_signals`). A recording whose URDF holds exactly its joints
    (more than one) is identified as one n-link robot (`mocapfj.ident.nlink`: each joint's motor
    equation, then the links' base parameters); otherwise each joint alone (`identify_signals`).
    Returns one dict per joint.
    """
    out = Path(out)
    rec = load_recording(recording)
    run_joints(recording, out / "joints")
    if method == "motor_first" and _urdf_chain(rec):
        return _identify_nlink(rec, out, decimate)
    results = []
    for i, spec in enumerate(rec.joints):
        t, q, q_m, u, n_filled = joint_signals(rec, out / "joints" / f"{spec.name}.angles.csv", i)
        try:
            res = identify_signals(t, q, q_m, u, rec.markers.rate_hz, method, cutoff_hz, decimate)
        except InputError as e:
            raise InputError(rec.root, f"joints[{spec.name}] ({e.field})", e.expected, e.got, e.hint) from None
        results.append({"name": spec.name, "recording": rec.name, "frames_filled": n_filled, **res})
    return results


def _param_table(trials: list[dict]) -> tuple[dict, dict | None]:
    """Per parameter {value, std, rel_std_pct}: one trial's LS statistics, or the mean and SD over trials."""
    names = [n for n in (*STEP1, "k") if all(n in t["values"] for t in trials)]
    vals = np.array([[t["values"][n][0] for n in names] for t in trials])
    if len(trials) == 1:
        std = np.array([trials[0]["values"][n][1] for n in names])
        cv = None
    else:
        std = vals.std(axis=0, ddof=1)
        cv = {n: float(100 * s / abs(m)) if m else None for n, m, s in zip(names, vals.mean(0), std)}
    mean = vals.mean(axis=0)
    params = {n: {"value": float(m), "std": float(s), "rel_std_pct": float(100 * s / abs(m)) if m else None}
              for n, m, s in zip(names, mean, std)}
    return params, cv


def _common_spring(trials: list[dict]) -> dict:
    """The spring model most trials chose (the earliest on a tie), with the first such trial's fit
    and how many trials chose it."""
    models = [t["spring"]["model"] for t in trials]
    best = max(dict.fromkeys(models), key=models.count)
    return {**next(t["spring"] for t in trials if t["spring"]["model"] == best), "n_trials_chosen": models.count(best)}


def run_identify(recordings, out: str | Path, method: str = "motor_first", cutoff_hz: float | None = None,
                 decimate: int = 2) -> dict:
    """``mocapfj identify``: identify every joint of one or more recordings; repeats give CV %.

    Writes OUT/<recording>/ (joints output), OUT/identify.json, and a seed-000-Table-I-style table
    OUT/table.md and OUT/table.csv (per joint: mean and, with repeats, CV % of I, c, v, mglx,
    mgly, b, J, k and the torque RMS error).
    """
    from ..io.atomic import write_text_atomic

    out = Path(out)
    per_joint: dict[str, list[dict]] = {}
    for k, r in enumerate(recordings):
        for res in identify_recording(r, out / f"{k:02d}_{Path(r).name}", method, cutoff_hz, decimate):
            per_joint.setdefault(res["name"], []).append(res)
    joints = []
    for name, trials in per_joint.items():
        params, cv = _param_table(trials)
        j = {"name": name, "method": trials[0]["method"], "params": params}
        for key in ("cond_two_step", "cond_one_step", "cond_motor", "cond_link", "torque_rms", "k_one_step"):
            if all(key in t for t in trials):
                j[key] = float(np.mean([t[key] for t in trials]))
        j.update(spring=_common_spring(trials), n_trials=len(trials),
                 frames_filled=int(sum(t["frames_filled"] for t in trials)))
        if cv is not None:
            j["cv_pct"] = cv
        joints.append(j)
    summary = {"recordings": [str(r) for r in recordings], "joints": joints}
    first = next(iter(per_joint.values()), [])
    if first and all("nlink" in t for t in first):   # the robot's base parameters, one set per recording
        runs = [t["nlink"] for t in first]
        names = list(runs[0]["base"])
        vals = np.array([[r["base"][n][0] for n in names] for r in runs])
        std = vals.std(axis=0, ddof=1) if len(runs) > 1 else np.array([runs[0]["base"][n][1] for n in names])
        summary["nlink"] = {
            "base_params": {n: {"value": float(v), "std": float(sd),
                                "rel_std_pct": float(100 * sd / abs(v)) if v else None}
                            for n, v, sd in zip(names, vals.mean(axis=0), std)},
            "cond": float(np.mean([r["cond"] for r in runs])), "torque_rms": float(np.mean([r["torque_rms"] for r in runs])),
            "r2": float(np.mean([r["r2"] for r in runs])), "n_trials": len(runs)}
    write_json(out / "identify.json", summary)
    # Table I of seed 000: columns I, c, v, mglx, mgly, b, J, k, error
    cols = ["I", "c", "v", "mglx", "mgly", "b", "J", "k"]
    units = ["kg m2", "N m", "N m s", "N m", "N m", "N m s", "kg m2", "N m/rad"]
    lines = ["| joint | statistic | " + " | ".join(f"{c} ({u})" for c, u in zip(cols, units)) + " | error (N m) |",
             "|" + "---|" * (len(cols) + 3)]
    csv_lines = ["joint,statistic," + ",".join(cols) + ",error"]
    for j in joints:
        p = j["params"]
        rows = [("mean", [p[c]["value"] if c in p else None for c in cols], j["torque_rms"])]
        rows.append(("CV (%)", [j["cv_pct"].get(c) for c in cols], None) if "cv_pct" in j
                    else ("rel. std (%)", [p[c]["rel_std_pct"] if c in p else None for c in cols], None))
        for stat, vals, err in rows:
            lines.append(f"| {j['name']} | {stat} | " + " | ".join("-" if v is None else f"{v:.4g}" for v in vals)
                         + f" | {'' if err is None else f'{err:.3g}'} |")
            csv_lines.append(",".join([j["name"], stat] + ["nan" if v is None else repr(float(v)) for v in vals]
                                      + ["" if err is None else repr(float(err))]))
    write_text_atomic(out / "table.md", "\n".join(lines) + "\n")
    write_text_atomic(out / "table.csv", "\n".join(csv_lines) + "\n")
    return summary
