"""Plain data types shared by every stage: one frozen dataclass per concept.

Arrays are fields; shapes and units are in each docstring and follow docs/conventions.md:
SI units, time axis first, NaN for a missing sample. The constructors check shapes once so that
the code inside the package can trust them. Dataclasses compare by identity (``eq=False``)
because their fields are arrays; tests compare fields with numpy.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import InputError

__all__ = [
    "MarkerTrajectories",
    "ControllerLog",
    "JointSpec",
    "Detections",
    "Camera",
    "Rig",
    "Board",
    "Recording",
    "JointGeometry",
    "JointAngles",
    "Deflection",
    "LSResult",
    "WORLD",
]

WORLD = "world"
"""`JointSpec.parent_markers` value for a joint whose parent link does not move."""


def _f64(x, shape_desc: str, name: str, ndim: int | None = None) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if ndim is not None and a.ndim != ndim:
        raise InputError(None, name, f"an array of shape {shape_desc}", f"shape {a.shape}")
    return a


def _freeze(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class MarkerTrajectories:
    """3D marker positions over time.

    Attributes
    ----------
    t : (T,) float
        Sample times in seconds on the mocap clock, strictly increasing.
    xyz : (T, M, 3) float
        Marker positions in metres in the mocap (world) frame; NaN where a marker is missing.
    labels : tuple of M str
        Marker labels, unique.
    rate_hz : float
        Nominal sampling rate in Hz.
    residual : (T, M) float or None
        Per-sample reconstruction residual in metres as reported by the mocap system
        (C3D POINT residual); NaN where the marker is missing. None when the source has none.
    """

    t: np.ndarray
    xyz: np.ndarray
    labels: tuple[str, ...]
    rate_hz: float
    residual: np.ndarray | None = None

    def __post_init__(self) -> None:
        t = _f64(self.t, "(T,)", "t", 1)
        xyz = _f64(self.xyz, "(T, M, 3)", "xyz", 3)
        labels = tuple(str(s) for s in self.labels)
        if xyz.shape[0] != t.shape[0] or xyz.shape[2] != 3 or xyz.shape[1] != len(labels):
            raise InputError(
                None, "xyz", f"shape (T={t.shape[0]}, M={len(labels)}, 3)", f"shape {xyz.shape}"
            )
        if len(set(labels)) != len(labels):
            dup = sorted({s for s in labels if labels.count(s) > 1})
            raise InputError(None, "labels", "unique marker labels", f"duplicates {dup}")
        if not (np.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise InputError(None, "rate_hz", "a positive rate in Hz", self.rate_hz)
        object.__setattr__(self, "t", _freeze(t))
        object.__setattr__(self, "xyz", _freeze(xyz))
        object.__setattr__(self, "labels", labels)
        object.__setattr__(self, "rate_hz", float(self.rate_hz))
        if self.residual is not None:
            r = _f64(self.residual, "(T, M)", "residual", 2)
            if r.shape != xyz.shape[:2]:
                raise InputError(None, "residual", f"shape {xyz.shape[:2]}", f"shape {r.shape}")
            object.__setattr__(self, "residual", _freeze(r))

    @property
    def n_frames(self) -> int:
        return int(self.t.shape[0])

    def index(self, label: str) -> int:
        """Column of `label` in `xyz`; raises InputError when absent."""
        try:
            return self.labels.index(label)
        except ValueError:
            raise InputError(None, "marker label", f"one of {list(self.labels)}", repr(label)) from None

    def select(self, labels) -> np.ndarray:
        """Positions of the given markers, (T, len(labels), 3) metres."""
        return self.xyz[:, [self.index(s) for s in labels], :]


@dataclass(frozen=True, eq=False)
class ControllerLog:
    """The robot controller's log: motor side of each joint, expressed on the link side.

    Attributes
    ----------
    t : (T,) float
        Sample times in seconds on the controller clock, strictly increasing.
    q_m : (T, J) float
        Motor angle divided by the gear ratio, rad (link side).
    tau : (T, J) float
        Motor torque times the gear ratio, N m (link side).
    joint_names : tuple of J str
    extra : mapping of str to (T,) float
        Any other logged columns, kept so that a bundle writes back losslessly.
    """

    t: np.ndarray
    q_m: np.ndarray
    tau: np.ndarray
    joint_names: tuple[str, ...]
    extra: Mapping[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        t = _f64(self.t, "(T,)", "t", 1)
        names = tuple(str(s) for s in self.joint_names)
        shape = (t.shape[0], len(names))
        q_m = _f64(self.q_m, "(T, J)", "q_m")
        tau = _f64(self.tau, "(T, J)", "tau")
        for name, a in (("q_m", q_m), ("tau", tau)):
            if a.shape != shape:
                raise InputError(None, name, f"shape {shape}", f"shape {a.shape}")
        extra = {}
        for k, v in dict(self.extra).items():
            v = _f64(v, "(T,)", f"extra[{k!r}]", 1)
            if v.shape[0] != t.shape[0]:
                raise InputError(None, f"extra[{k!r}]", f"{t.shape[0]} samples", v.shape[0])
            extra[str(k)] = _freeze(v)
        object.__setattr__(self, "t", _freeze(t))
        object.__setattr__(self, "q_m", _freeze(q_m))
        object.__setattr__(self, "tau", _freeze(tau))
        object.__setattr__(self, "joint_names", names)
        object.__setattr__(self, "extra", extra)

    @property
    def n_samples(self) -> int:
        return int(self.t.shape[0])

    @property
    def rate_hz(self) -> float:
        """Median sampling rate in Hz."""
        return float(1.0 / np.median(np.diff(self.t))) if self.t.size > 1 else float("nan")


@dataclass(frozen=True, eq=False)
class JointSpec:
    """How one joint appears in a recording (the ``[[joints]]`` table of recording.toml).

    Attributes
    ----------
    name : str
    motor_position, motor_torque : str
        Controller CSV columns: motor angle / gear ratio (rad) and motor torque x gear ratio (N m).
    gear_ratio : float
        Informative: the logged columns are already on the link side.
    link_markers : tuple of str
        Labels of the markers on the link this joint moves.
    parent_markers : tuple of str, or the string ``"world"``
        Labels of the markers on the parent link, or ``"world"`` when the parent does not move.
    extra : mapping
        Keys of the table that this version does not interpret; written back unchanged.
    """

    name: str
    motor_position: str
    motor_torque: str
    gear_ratio: float
    link_markers: tuple[str, ...]
    parent_markers: tuple[str, ...] | str = WORLD
    extra: Mapping[str, object] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "link_markers", tuple(self.link_markers))
        if not isinstance(self.parent_markers, str):
            object.__setattr__(self, "parent_markers", tuple(self.parent_markers))
        object.__setattr__(self, "gear_ratio", float(self.gear_ratio))
        object.__setattr__(self, "extra", dict(self.extra))

    @property
    def parent_is_world(self) -> bool:
        return isinstance(self.parent_markers, str)


@dataclass(frozen=True, eq=False)
class Detections:
    """2D detections from several cameras, one row per detected point.

    Attributes
    ----------
    frame : (N,) int
        Frame index (0-based) in the camera clip.
    camera : (N,) int
        Camera number, as in the rig (``cam_<number>``).
    xy_px : (N, 2) float
        Image position in pixels, OpenCV convention (origin at the centre of the top-left pixel).
    point_id : (N,) int
        Identity of the 3D point when known (marker index, board corner id), -1 when unlabelled.
    """

    frame: np.ndarray
    camera: np.ndarray
    xy_px: np.ndarray
    point_id: np.ndarray

    def __post_init__(self) -> None:
        xy = _f64(self.xy_px, "(N, 2)", "xy_px", 2)
        n = xy.shape[0]
        if xy.shape[1] != 2:
            raise InputError(None, "xy_px", "shape (N, 2)", f"shape {xy.shape}")
        for name in ("frame", "camera", "point_id"):
            a = np.asarray(getattr(self, name))
            if a.shape != (n,):
                raise InputError(None, name, f"shape ({n},)", f"shape {a.shape}")
            object.__setattr__(self, name, _freeze(a.astype(np.int64)))
        object.__setattr__(self, "xy_px", _freeze(xy))


@dataclass(frozen=True, eq=False)
class Camera:
    """A calibrated pinhole camera with OpenCV distortion.

    Attributes
    ----------
    name : str
    size : (width, height) int
        Image size in pixels.
    K : (3, 3) float
        Intrinsic matrix, pixels.
    dist : (k,) float
        OpenCV distortion coefficients (k1, k2, p1, p2[, k3, ...]).
    R_cam_world : (3, 3) float
        Rotation mapping world coordinates into the camera frame: p_cam = R p_world + t.
    t_cam_world : (3,) float
        Translation of the same map, metres.
    """

    name: str
    size: tuple[int, int]
    K: np.ndarray
    dist: np.ndarray
    R_cam_world: np.ndarray
    t_cam_world: np.ndarray

    def __post_init__(self) -> None:
        for name, shape in (("K", (3, 3)), ("R_cam_world", (3, 3)), ("t_cam_world", (3,))):
            a = np.asarray(getattr(self, name), dtype=np.float64)
            if a.shape != shape:
                raise InputError(None, f"camera {self.name!r} {name}", f"shape {shape}", f"shape {a.shape}")
            object.__setattr__(self, name, _freeze(a))
        object.__setattr__(self, "dist", _freeze(np.asarray(self.dist, dtype=np.float64).ravel()))
        object.__setattr__(self, "size", (int(self.size[0]), int(self.size[1])))


@dataclass(frozen=True, eq=False)
class Rig:
    """Calibrated cameras, ordered by camera number.

    Attributes
    ----------
    cameras : tuple of Camera
    metadata : mapping
        Free-form facts from the rig file (residuals, uncertainty, the tool that made it).
    """

    cameras: tuple[Camera, ...]
    metadata: Mapping[str, object] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "cameras", tuple(self.cameras))
        object.__setattr__(self, "metadata", dict(self.metadata))


BOARD_TYPES = ("chessboard", "charuco", "aprilgrid")


@dataclass(frozen=True, eq=False)
class Board:
    """A planar calibration target (``calibration/boards/*.toml``).

    Attributes
    ----------
    type : {"chessboard", "charuco", "aprilgrid"}
    columns, rows : int
        Inner corners (chessboard) or squares/tags (charuco, aprilgrid) along x and y.
    square_m : float
        Square size, metres (chessboard, charuco).
    marker_m : float or None
        ArUco marker side, metres (charuco).
    dictionary : str or None
        OpenCV ArUco dictionary name, e.g. ``"DICT_4X4_1000"`` (charuco, aprilgrid).
    inverted : bool
        The board is printed white-on-black: invert the grey image before detection.
    tag_m, spacing_m : float or None
        Tag side and gap between tags, metres (aprilgrid).
    family : str or None
        AprilTag family, e.g. ``"tag36h11"`` (aprilgrid).
    """

    type: str
    columns: int
    rows: int
    square_m: float | None = None
    marker_m: float | None = None
    dictionary: str | None = None
    inverted: bool = False
    tag_m: float | None = None
    spacing_m: float | None = None
    family: str | None = None


@dataclass(frozen=True, eq=False)
class Recording:
    """A loaded recording bundle (a directory with recording.toml; docs/formats.md).

    Attributes
    ----------
    name : str
    markers : MarkerTrajectories
        On the mocap clock.
    controller : ControllerLog
        On the controller clock: t_controller = t_mocap + clock_offset_s.
    joints : tuple of JointSpec
    clock_offset_s : float
        Declared offset between the clocks (hardware sync); 0 when not declared.
    marker_file, controller_file : str
        File names inside the bundle.
    time_column : str
        Controller CSV column holding time in seconds.
    urdf : Path or None
        Robot description, when the bundle has one.
    rig : Rig or None
    detections : Detections or None
    root : Path or None
        The bundle directory it was read from.
    spec : mapping
        The parsed recording.toml, including keys this version does not interpret; the writer
        starts from it, so a bundle writes back losslessly.
    """

    name: str
    markers: MarkerTrajectories
    controller: ControllerLog
    joints: tuple[JointSpec, ...]
    clock_offset_s: float = 0.0
    marker_file: str = "markers.c3d"
    controller_file: str = "controller.csv"
    time_column: str = "time"
    urdf: Path | None = None
    rig: Rig | None = None
    detections: Detections | None = None
    root: Path | None = None
    spec: Mapping[str, object] = field(default_factory=dict)

    def joint(self, name: str) -> JointSpec:
        for j in self.joints:
            if j.name == name:
                return j
        raise InputError(self.root, "joints", f"one of {[j.name for j in self.joints]}", repr(name))

    def markers_t_controller(self) -> np.ndarray:
        """Mocap sample times on the controller clock, (T,) s."""
        return self.markers.t + self.clock_offset_s


@dataclass(frozen=True, eq=False)
class JointGeometry:
    """A revolute joint calibrated from a marker cluster (docs/conventions.md).

    The link's markers move about the joint in the frame of the parent (the world when the parent
    does not move): at link angle q, marker p is at ``point + R(axis, q) @ template[p]`` (rotation
    by q about `axis`, right hand), with q = 0 where the template was taken.

    Attributes
    ----------
    axis : (3,) float
        Unit axis direction in the parent frame.
    point : (3,) float
        The point of the axis closest to the markers' centroid (foot of the perpendicular), metres.
    template : (P, 3) float
        Marker positions relative to `point` at q = 0, parent frame, metres, in `labels` order.
    labels : tuple of P str
    radii : (P,) float
        Distance of each marker from the axis, metres (r_p).
    radius_rms : (P,) float
        RMS of each marker's distance from the axis over the calibration frames minus r_p, metres.
    marker_rms : float
        RMS of the marker residuals of the fit, metres.
    cov_axis : (3, 3) float
        Uncertainty of `axis` (rank 2: tilt), rad^2: the covariance from the Fisher information
        for the maximum-likelihood fit; for the algebraic fits a parametric-bootstrap mean-square
        error, which includes their bias (NaN when the bootstrap was switched off).
    cov_point : (3, 3) float
        Uncertainty of `point` (rank 2: in the plane normal to the axis), m^2, as for `cov_axis`.
    sigma_m : float
        Marker noise SD the fit estimated (or was given), metres per coordinate.
    method : str
        "gamage_lasenby", "halvorsen", "ml", "sara" or "score".
    n_frames : int
        Frames used.
    """

    axis: np.ndarray
    point: np.ndarray
    template: np.ndarray
    labels: tuple[str, ...]
    radii: np.ndarray
    radius_rms: np.ndarray
    marker_rms: float
    cov_axis: np.ndarray
    cov_point: np.ndarray
    sigma_m: float
    method: str
    n_frames: int

    def __post_init__(self) -> None:
        for name in ("axis", "point", "template", "radii", "radius_rms", "cov_axis", "cov_point"):
            object.__setattr__(self, name, _freeze(np.asarray(getattr(self, name), dtype=np.float64)))
        object.__setattr__(self, "labels", tuple(self.labels))
        P = len(self.labels)
        if self.axis.shape != (3,) or self.point.shape != (3,) or self.template.shape != (P, 3):
            raise InputError(None, "JointGeometry", f"axis (3,), point (3,), template ({P}, 3)",
                             f"{self.axis.shape}, {self.point.shape}, {self.template.shape}")


@dataclass(frozen=True, eq=False)
class JointAngles:
    """Per-frame link angles of one joint.

    Attributes
    ----------
    t : (T,) float
        Sample times, seconds (the clock of the markers they came from).
    q : (T,) float
        Link angle, rad, unwrapped; NaN where the frame had too few valid markers.
    sigma_q : (T,) float
        Cramér-Rao SD of each angle, sigma / sqrt(sum of r_p^2 over the markers used), rad.
    marker_rms : (T,) float
        RMS residual of the markers used in each frame, metres.
    n_markers : (T,) int
        Markers used in each frame (after outlier rejection).
    n_rejected : (T,) int
        Markers rejected as outliers in each frame.
    """

    t: np.ndarray
    q: np.ndarray
    sigma_q: np.ndarray
    marker_rms: np.ndarray
    n_markers: np.ndarray
    n_rejected: np.ndarray

    @property
    def n_invalid(self) -> int:
        return int(np.isnan(self.q).sum())


@dataclass(frozen=True, eq=False)
class Deflection:
    """Joint deflection on the controller clock at the mocap samples (docs/conventions.md).

    Attributes
    ----------
    t : (T,) float
        Controller-clock times of the mocap samples (declared clock offset applied), s.
    q : (T,) float
        Link angle from mocap with its zero aligned to the motor's (``q_offset_rad`` added), rad.
    q_m : (T,) float
        Motor angle / gear ratio interpolated at `t`, rad.
    delta : (T,) float
        q_m - q, rad; NaN where either is missing.
    sigma_delta : (T,) float
        Per-sample SD of delta: link-angle CRLB and motor quantisation combined, rad.
    tau : (T,) float
        Logged motor torque (link side) interpolated at `t`, N m.
    q_offset_rad : float
        Constant added to the mocap angle (the two angle zeros differ by the mounting of the
        markers; kinematics cannot tell it from a constant spring offset, so it is set so that the
        mean deflection is zero and identification fits the spring's offset).
    q_m_quantum_rad : float
        Quantum of the logged q_m estimated from its smallest step (0 if not quantised), rad.
    """

    t: np.ndarray
    q: np.ndarray
    q_m: np.ndarray
    delta: np.ndarray
    sigma_delta: np.ndarray
    tau: np.ndarray
    q_offset_rad: float
    q_m_quantum_rad: float


@dataclass(frozen=True, eq=False)
class LSResult:
    """A least-squares identification with its statistics (seed 003 eq. 15-17).

    Attributes
    ----------
    names : tuple of p str
    values : (p,) float
        Estimates, SI units of each parameter.
    std : (p,) float
        Standard deviations, sqrt(diag(cov)).
    rel_std_pct : (p,) float
        100 std / |value| (NaN where the value is 0).
    cov : (p, p) float
        sigma_rho^2 (W^T W)^-1 with sigma_rho^2 = ||y - W x||^2 / (r - p).
    cond : float
        Condition number of the (weighted) observation matrix, columns unscaled.
    residual_rms : float
        RMS of y - W x, units of y.
    rel_error_pct : float
        100 ||y - W x|| / ||y||.
    r2 : float
        1 - ||y - W x||^2 / ||y - mean(y)||^2.
    n_samples : int
    unidentifiable : tuple of str
        Parameters the data cannot separate (rank deficiency); their values are NaN.
    """

    names: tuple[str, ...]
    values: np.ndarray
    std: np.ndarray
    rel_std_pct: np.ndarray
    cov: np.ndarray
    cond: float
    residual_rms: float
    rel_error_pct: float
    r2: float
    n_samples: int
    unidentifiable: tuple[str, ...] = ()

    def __getitem__(self, name: str) -> float:
        return float(self.values[self.names.index(name)])
