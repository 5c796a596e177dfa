"""What identification returns: typed, frozen results with ``to_dict()`` (the ``--json`` keys of
``mocapfj identify``, README and docs/identification.md).

- :class:`Parameter`: one identified parameter with its standard deviation and whether the data
  determine it (and why not).
- :class:`SpringResult`: the spring model chosen for a joint.
- :class:`IdentifiedJoint`: one joint of one recording: its parameters, the least-squares results
  of each stage, the spring, and a :class:`mocapfj.dynamics.JointModel` that
  :func:`mocapfj.dynamics.simulate` and discovery take as is.
- :class:`JointSummary`: one joint over repeated recordings (mean, SD, CV %).
- :class:`Identification`: a whole ``identify`` run.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..dynamics import JointModel
from ..errors import InputError
from ..types import LSResult

__all__ = ["PARAMETER_NAMES", "PARAMETER_UNITS", "UNDETERMINED_REL_STD_PCT", "Parameter", "SpringResult", "IdentifiedJoint", "JointSummary",
           "RigidJointFit", "RigidIdentification", "Identification", "summarize_trials"]

PARAMETER_NAMES = ("I", "mglx", "mgly", "c", "v", "J", "b", "k")
"""The single-joint parameters of Lightcap and Banks (2007) eq. (4), in the order of its Table I
columns as mocapfj reports them."""

UNDETERMINED_REL_STD_PCT = 5.0
"""A parameter whose SD exceeds this share of its value is reported as not determined."""

PARAMETER_UNITS = {"I": "kg m2", "mglx": "N m", "mgly": "N m", "c": "N m", "v": "N m s", "J": "kg m2",
                   "b": "N m s", "k": "N m/rad"}


def _rel_pct(value: float, std: float) -> float | None:
    return float(100.0 * std / abs(value)) if value and np.isfinite(value) and np.isfinite(std) else None


@dataclass(frozen=True)
class Parameter:
    """An identified parameter: value and standard deviation (SI units of `name`, PARAMETER_UNITS).

    determined : False when the data do not determine it (not excited, or a relative SD above the
        threshold the estimator states); `reason` then says why and, where it can, which
        excitation would.
    """

    name: str
    value: float
    std: float
    determined: bool = True
    reason: str | None = None

    @property
    def rel_std_pct(self) -> float | None:
        return _rel_pct(self.value, self.std)

    def to_dict(self) -> dict:
        out = {"value": float(self.value), "std": float(self.std), "rel_std_pct": self.rel_std_pct,
               "determined": bool(self.determined)}
        if not self.determined:
            out["reason"] = self.reason
        return out


@dataclass(frozen=True, eq=False)
class SpringResult:
    """The spring model chosen for a joint.

    model : "linear", "cubic", "piecewise", "backlash", "bouc_wen", "dahl" or "maxwell_slip".
    params : {name: value} in SI units (docs/identification.md lists them per model).
    element : the :mod:`mocapfj.dynamics` element with these coefficients (offsets excluded).
    r2 : coefficient of determination on the held-out spring samples (or on all of them for a
        spring found in the motor equation); None when not measured.
    holdout_rms_Nm : {model: held-out RMS error, N m} of every model tried, when selected by
        held-out error.
    motor_rms_gain_pct : for a hysteretic spring found in the motor equation, how much it lowered
        that equation's residual RMS, %.
    """

    model: str
    params: Mapping[str, float]
    element: object
    r2: float | None = None
    holdout_rms_Nm: Mapping[str, float] | None = None
    motor_rms_gain_pct: float | None = None

    def to_dict(self) -> dict:
        out = {"model": self.model, "params": {k: float(v) for k, v in self.params.items()}}
        if self.r2 is not None:
            out["r2"] = float(self.r2)
        if self.holdout_rms_Nm is not None:
            out["holdout_rms_Nm"] = {k: float(v) for k, v in self.holdout_rms_Nm.items()}
        if self.motor_rms_gain_pct is not None:
            out["motor_rms_gain_pct"] = float(self.motor_rms_gain_pct)
        return out


@dataclass(frozen=True, eq=False)
class IdentifiedJoint:
    """One joint of one recording identified (:func:`mocapfj.ident.identify_joint`).

    Attributes
    ----------
    name : str
    method : str
        The estimator whose parameters are reported (docs/identification.md).
    params : {name: Parameter}
        I, mglx, mgly, c, v, J, b, k (those the method gives), SI units.
    model : JointModel or None
        The identified model (the chosen spring, Coulomb and viscous friction), ready for
        :func:`mocapfj.dynamics.simulate` and :func:`mocapfj.discover.discover`; None for a joint
        identified as part of an n-link robot (its links are the URDF's).
    spring : SpringResult
    stages : {stage: LSResult}
        The least-squares results the method went through (e.g. "motor", "link"; "step1",
        "spring", "one_step" for the two-step method).
    cond : {name: float}
        Condition numbers (``cond_two_step``, ``cond_one_step`` of Lightcap and Banks (2007) and the
        method's own).
    torque_rms : float
        RMS torque residual of the method's main equation, N m.
    q_zero_rad : float
        The link angle's zero minus the spring's zero, rad (mocap cannot tell them apart).
    k_one_step : float or None
        The one-step estimate of k, N m/rad.
    frames_filled : int
        Link-angle samples filled across short gaps.
    recording : str
    extra : dict
        Further JSON entries (e.g. ``nlink`` for joints identified as one robot).
    """

    name: str
    method: str
    params: Mapping[str, Parameter]
    model: JointModel | None
    spring: SpringResult
    stages: Mapping[str, LSResult] = field(default_factory=dict)
    cond: Mapping[str, float] = field(default_factory=dict)
    torque_rms: float = float("nan")
    q_zero_rad: float = 0.0
    k_one_step: float | None = None
    frames_filled: int = 0
    recording: str = ""
    extra: Mapping[str, object] = field(default_factory=dict)

    def __getitem__(self, name: str) -> float:
        return self.params[name].value

    def to_dict(self) -> dict:
        """This trial's entry: name, method, params {name: {value, std, rel_std_pct}}, cond_*,
        torque_rms, k_one_step, spring, frames_filled, recording."""
        out = {"name": self.name, "recording": self.recording, "method": self.method,
               "params": {n: p.to_dict() for n, p in self.params.items()}}
        out.update({k: float(v) for k, v in self.cond.items()})
        out["torque_rms"] = float(self.torque_rms)
        if self.k_one_step is not None:
            out["k_one_step"] = float(self.k_one_step)
        out.update(q_zero_rad=float(self.q_zero_rad), spring=self.spring.to_dict(), frames_filled=int(self.frames_filled))
        out.update(self.extra)
        return out


@dataclass(frozen=True, eq=False)
class JointSummary:
    """One joint over one or more recordings: with one trial its least-squares statistics, with
    repeats the mean, the SD over trials and the CV % (as Table I of Lightcap and Banks 2007)."""

    name: str
    trials: tuple[IdentifiedJoint, ...]

    @property
    def params(self) -> dict[str, Parameter]:
        names = [n for n in PARAMETER_NAMES if all(n in t.params for t in self.trials)]
        if len(self.trials) == 1:
            return {n: self.trials[0].params[n] for n in names}
        out = {}
        for n in names:
            vals = np.array([t.params[n].value for t in self.trials])
            und = [t.params[n] for t in self.trials if not t.params[n].determined]
            out[n] = Parameter(n, float(vals.mean()), float(vals.std(ddof=1)), determined=not und,
                               reason=und[0].reason if und else None)
        return out

    @property
    def cv_pct(self) -> dict[str, float | None] | None:
        if len(self.trials) < 2:
            return None
        return {n: p.rel_std_pct for n, p in self.params.items()}

    @property
    def spring(self) -> dict:
        """The spring model most trials chose (the earliest on a tie), with the first such
        trial's fit and how many trials chose it."""
        models = [t.spring.model for t in self.trials]
        best = max(dict.fromkeys(models), key=models.count)
        first = next(t.spring for t in self.trials if t.spring.model == best)
        return {**first.to_dict(), "n_trials_chosen": models.count(best)}

    def to_dict(self) -> dict:
        first = self.trials[0]
        out = {"name": self.name, "method": first.method, "params": {n: p.to_dict() for n, p in self.params.items()}}
        for key in first.cond:
            if all(key in t.cond for t in self.trials):
                out[key] = float(np.mean([t.cond[key] for t in self.trials]))
        out["torque_rms"] = float(np.mean([t.torque_rms for t in self.trials]))
        if all(t.k_one_step is not None for t in self.trials):
            out["k_one_step"] = float(np.mean([t.k_one_step for t in self.trials]))
        out.update(spring=self.spring, n_trials=len(self.trials),
                   frames_filled=int(sum(t.frames_filled for t in self.trials)))
        if self.cv_pct is not None:
            out["cv_pct"] = self.cv_pct
        elif first.extra:
            out.update({k: v for k, v in first.extra.items() if k not in out})
        not_determined = {n: p.reason for n, p in self.params.items() if not p.determined}
        if not_determined:
            out["not_determined"] = not_determined
        return out


def summarize_trials(trials: Sequence[IdentifiedJoint]) -> list[JointSummary]:
    """Group trials by joint name, in order of first appearance."""
    groups: dict[str, list[IdentifiedJoint]] = {}
    for t in trials:
        groups.setdefault(t.name, []).append(t)
    return [JointSummary(name, tuple(ts)) for name, ts in groups.items()]


@dataclass(frozen=True, eq=False)
class RigidJointFit:
    """One joint of a rigid robot: its friction model and torque residuals."""

    name: str
    friction: str
    friction_params: Mapping[str, float]
    torque_rms: float
    validation_torque_rms: float | None = None

    def to_dict(self) -> dict:
        out = {"name": self.name, "method": "rigid_nlink", "friction": self.friction,
               "friction_params": {k: float(v) for k, v in self.friction_params.items()},
               "torque_rms": float(self.torque_rms)}
        if self.validation_torque_rms is not None:
            out["validation_torque_rms"] = float(self.validation_torque_rms)
        return out


@dataclass(frozen=True, eq=False)
class RigidIdentification:
    """A rigid robot identified from its controller log and URDF (:mod:`mocapfj.ident.rigid`).

    base : LSResult of the base parameters (regrouped names) and the friction parameters.
    joints : per joint, the friction model chosen and the torque RMS.
    friction_scores : {model: held-out torque RMS, N m} of every friction model tried.
    n_resampled : samples whose time stamps were off the uniform grid and were resampled.
    base_idx, Kd, standard_names : the regrouping (:func:`mocapfj.ident.regressor.base_parameters`).
    joint_names, friction_scale (eps or vs of the friction law, rad/s), cutoff_hz, sign_eps: the
        settings, to apply the model to another log (:func:`mocapfj.ident.rigid.torque_rms_on`).
    validation : {joint: torque RMS on the validation recording, N m} or None.
    """

    base: LSResult
    joints: tuple[RigidJointFit, ...]
    friction: str
    friction_scores: Mapping[str, float]
    fs_hz: float
    n_samples: int
    n_resampled: int
    base_idx: np.ndarray
    Kd: np.ndarray
    standard_names: tuple[str, ...]
    joint_names: tuple[str, ...] = ()
    friction_scale: float | None = None
    cutoff_hz: float = float("nan")
    sign_eps: float = 0.0
    validation: Mapping[str, float] | None = None

    @property
    def params(self) -> dict[str, Parameter]:
        """The base and friction parameters; one whose relative SD exceeds `UNDETERMINED_REL_STD_PCT`
        is marked not determined (the trajectory hardly excites it)."""
        b = self.base
        out = {}
        for n, v, s in zip(b.names, b.values, b.std):
            rel = 100 * s / abs(v) if v else np.inf
            det = bool(rel <= UNDETERMINED_REL_STD_PCT)
            out[n] = Parameter(n, float(v), float(s), determined=det,
                               reason=None if det else f"relative SD {rel:.3g} % above {UNDETERMINED_REL_STD_PCT:g} %: "
                                                       "the trajectory hardly excites it (its torque is near the noise)")
        return out

    def to_dict(self) -> dict:
        b = self.base
        return {"base_params": {n: p.to_dict() for n, p in self.params.items()},
                "cond": float(b.cond), "torque_rms": float(b.residual_rms), "r2": float(b.r2),
                "friction": self.friction, "friction_holdout_rms_Nm": {k: float(v) for k, v in self.friction_scores.items()},
                "fs_hz": float(self.fs_hz), "cutoff_hz": float(self.cutoff_hz), "n_samples": int(self.n_samples),
                "n_resampled": int(self.n_resampled)}


@dataclass(frozen=True, eq=False)
class Identification:
    """A whole ``identify`` run: every joint of every recording (:func:`mocapfj.identify`).

    recordings : the recordings' names or paths.
    joints : per joint, its trials (:class:`JointSummary`).
    nlink : {recording: dict} for robots identified through their URDF (the links' base
        parameters), else empty.
    rigid : the rigid-robot identification of each recording that has no markers, else empty.
    """

    recordings: tuple[str, ...]
    joints: tuple[JointSummary, ...]
    nlink: tuple[dict, ...] = ()
    rigid: tuple[RigidIdentification, ...] = ()

    def joint(self, name: str) -> JointSummary:
        for j in self.joints:
            if j.name == name:
                return j
        raise InputError(None, "joint", f"one of {[j.name for j in self.joints]}", repr(name))

    def to_dict(self) -> dict:
        """identify.json: recordings, joints [...], and nlink / rigid when present."""
        out = {"recordings": list(self.recordings), "joints": [j.to_dict() for j in self.joints]}
        if self.nlink:
            out["nlink"] = _nlink_summary(self.nlink)
        if self.rigid:
            out["joints"] = [jf.to_dict() for jf in self.rigid[0].joints]
            out["rigid"] = self.rigid[0].to_dict()
            if self.rigid[0].validation is not None:
                out["validation"] = dict(self.rigid[0].validation)
            if len(self.rigid) > 1:
                out["rigid_trials"] = [r.to_dict() for r in self.rigid]
        return out


def _nlink_summary(runs: Sequence[dict]) -> dict:
    """The links' base parameters, one set per recording: LS statistics for one, mean and SD over
    several."""
    names = list(runs[0]["base"])
    vals = np.array([[r["base"][n][0] for n in names] for r in runs])
    std = vals.std(axis=0, ddof=1) if len(runs) > 1 else np.array([runs[0]["base"][n][1] for n in names])
    return {"base_params": {n: Parameter(n, float(v), float(sd)).to_dict() for n, v, sd in zip(names, vals.mean(axis=0), std)},
            "cond": float(np.mean([r["cond"] for r in runs])), "torque_rms": float(np.mean([r["torque_rms"] for r in runs])),
            "r2": float(np.mean([r["r2"] for r in runs])), "n_trials": len(runs)}
