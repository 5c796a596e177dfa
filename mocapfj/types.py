"""Plain data types shared by every stage: one frozen dataclass per concept.

Arrays are fields; shapes and units are in each docstring and follow docs/conventions.md:
SI units, time axis first, NaN for a missing sample. The constructors check shapes once so that
the code inside the package can trust them: every constructor checks its arrays' shapes (named
sizes agree across fields) with the ``check_*`` validators of :mod:`mocapfj.validate` and stores
read-only copies. Dataclasses compare by identity (``eq=False``) because their fields are arrays;
tests compare fields with numpy.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import InputError
from .validate import check_array, check_int, check_scalar, freeze

__all__ = [
    "MarkerTrajectories",
    "ControllerLog",
    "JointSpec",
    "Detections",
    "Camera",
    "Rig",
    "Board",
    "Wand",
    "MarkerCluster",
    "Recording",
    "JointGeometry",
    "JointAngles",
    "Deflection",
    "LSResult",
    "JointSignals",
    "WORLD",
]

WORLD = "world"
"""`JointSpec.parent_markers` value for a joint whose parent link does not move."""


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
        labels = tuple(str(s) for s in self.labels)
        dims = {"M": len(labels)}
        t = check_array(self.t, "t", ("T",), dims=dims)
        xyz = check_array(self.xyz, "xyz", ("T", "M", 3), dims=dims)
        if len(set(labels)) != len(labels):
            dup = sorted({s for s in labels if labels.count(s) > 1})
            raise InputError(None, "labels", "unique marker labels", f"duplicates {dup}")
        object.__setattr__(self, "t", freeze(t))
        object.__setattr__(self, "xyz", freeze(xyz))
        object.__setattr__(self, "labels", labels)
        object.__setattr__(self, "rate_hz", check_scalar(self.rate_hz, "rate_hz", positive=True))
        if self.residual is not None:
            object.__setattr__(self, "residual", freeze(check_array(self.residual, "residual", ("T", "M"), dims=dims)))

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
    time_note : str or None
        What the reader did to the time stamps (a jittered stamping of a uniform log replaced by
        its uniform tick), or None.
    """

    t: np.ndarray
    q_m: np.ndarray
    tau: np.ndarray
    joint_names: tuple[str, ...]
    extra: Mapping[str, np.ndarray] = field(default_factory=dict)
    time_note: str | None = None

    def __post_init__(self) -> None:
        names = tuple(str(s) for s in self.joint_names)
        dims = {"J": len(names)}
        t = check_array(self.t, "t", ("T",), dims=dims)
        q_m = check_array(self.q_m, "q_m", ("T", "J"), dims=dims)
        tau = check_array(self.tau, "tau", ("T", "J"), dims=dims)
        extra = {str(k): freeze(check_array(v, f"extra[{k!r}]", ("T",), dims=dims)) for k, v in dict(self.extra).items()}
        object.__setattr__(self, "t", freeze(t))
        object.__setattr__(self, "q_m", freeze(q_m))
        object.__setattr__(self, "tau", freeze(tau))
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
        Controller CSV columns: motor angle / gear ratio (rad) and motor torque x gear ratio (N m);
        empty for a joint without a motor log (a passive hinge, a human joint).
    gear_ratio : float
        Informative: the logged columns are already on the link side.
    link_markers : tuple of str
        Labels of the markers on the link this joint moves; empty for a joint known only from the
        controller log (a rigid robot identified from its log and URDF).
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
        object.__setattr__(self, "link_markers", tuple(str(s) for s in self.link_markers))
        if isinstance(self.parent_markers, str):
            if self.parent_markers != WORLD:
                raise InputError(None, f"joints[{self.name}].parent_markers", f'marker labels or "{WORLD}"',
                                 repr(self.parent_markers))
        else:
            object.__setattr__(self, "parent_markers", tuple(str(s) for s in self.parent_markers))
        object.__setattr__(self, "gear_ratio", check_scalar(self.gear_ratio, f"joints[{self.name}].gear_ratio",
                                                            positive=True))
        object.__setattr__(self, "extra", dict(self.extra))

    @property
    def parent_is_world(self) -> bool:
        return isinstance(self.parent_markers, str)

    @property
    def has_markers(self) -> bool:
        """The joint's link carries markers (False in a rigid-robot bundle: controller log only)."""
        return bool(self.link_markers)

    @property
    def has_motor(self) -> bool:
        """The controller log has this joint's motor columns (False for a passive hinge)."""
        return bool(self.motor_position) and bool(self.motor_torque)


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
        dims = {}
        xy = check_array(self.xy_px, "xy_px", ("N", 2), dims=dims)
        for name in ("frame", "camera", "point_id"):
            a = check_array(getattr(self, name), name, ("N",), dims=dims, dtype=np.int64)
            object.__setattr__(self, name, freeze(a))
        object.__setattr__(self, "xy_px", freeze(xy))


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
            object.__setattr__(self, name, freeze(check_array(getattr(self, name), f"camera {self.name!r} {name}",
                                                              shape, finite=True)))
        object.__setattr__(self, "dist", freeze(check_array(self.dist, f"camera {self.name!r} dist", finite=True).ravel()))
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
class Wand:
    """A calibration wand and its L-frame (``calibration/wands/*.toml``; docs/formats.md).

    Attributes
    ----------
    markers_m : (K,) float
        Positions of the wand's K >= 2 collinear markers along it, metres from its first marker:
        0 first, strictly increasing (the wand length is the last).
    lframe_m : (L, 3) float or None
        Positions of the L-frame's L >= 3 markers in the world frame it defines (origin and axes),
        metres; None when the wand comes without one.
    name : str
    """

    markers_m: np.ndarray
    lframe_m: np.ndarray | None = None
    name: str = "wand"

    def __post_init__(self) -> None:
        m = check_array(self.markers_m, "wand markers_m", ("K",), finite=True)
        if m.size < 2 or m[0] != 0.0 or not (np.diff(m) > 0).all():
            raise InputError(None, "wand markers_m", "at least 2 distances along the wand from its first marker, "
                             "starting at 0 and strictly increasing (m)", m.tolist())
        object.__setattr__(self, "markers_m", freeze(m))
        if self.lframe_m is not None:
            L = check_array(self.lframe_m, "lframe markers_m", ("L", 3), finite=True)
            centred = L - L.mean(axis=0) if L.shape[0] else L
            if L.shape[0] < 3 or np.linalg.svd(centred, compute_uv=False)[1] < 1e-3 * max(np.abs(centred).max(), 1e-12):
                raise InputError(None, "lframe markers_m", "at least 3 marker positions (m), not all on one line",
                                 L.tolist())
            object.__setattr__(self, "lframe_m", freeze(L))
        object.__setattr__(self, "name", str(self.name))

    @property
    def length_m(self) -> float:
        """Distance between the first and the last marker, m."""
        return float(self.markers_m[-1])


@dataclass(frozen=True, eq=False)
class MarkerCluster:
    """A rigid cluster of markers (a clusters file's ``[[clusters]]`` or ``[[tags]]``; docs/formats.md).

    Attributes
    ----------
    name : str
    labels : tuple of K str
        Marker labels, unique (a tag's corners are ``<name>_0`` .. ``<name>_3``).
    template_m : (K, 3) float
        Marker positions in the cluster's own frame, metres; K >= 3, not all on one line.
    tag_id : int or None
        For an AprilTag: its id (its corners are the markers, in OpenCV's order).
    tag_family : str or None
        For an AprilTag: its family ("tag36h11").
    """

    name: str
    labels: tuple[str, ...]
    template_m: np.ndarray
    tag_id: int | None = None
    tag_family: str | None = None

    def __post_init__(self) -> None:
        labels = tuple(str(s) for s in self.labels)
        where = f"cluster {self.name!r}"
        tpl = check_array(self.template_m, f"{where} template_m", (len(labels), 3), finite=True)
        if len(set(labels)) != len(labels):
            raise InputError(None, f"{where} labels", "unique marker labels", sorted({s for s in labels if labels.count(s) > 1}))
        centred = tpl - tpl.mean(axis=0) if tpl.shape[0] else tpl
        sv = np.linalg.svd(centred, compute_uv=False) if tpl.shape[0] >= 2 else np.zeros(2)
        if tpl.shape[0] < 3 or sv[1] < 1e-3 * max(sv[0], 1e-12):
            raise InputError(None, f"{where} template_m", "at least 3 marker positions (m), not all on one line",
                             f"{tpl.shape[0]} markers")
        object.__setattr__(self, "name", str(self.name))
        object.__setattr__(self, "labels", labels)
        object.__setattr__(self, "template_m", freeze(tpl))
        if self.tag_id is not None:
            object.__setattr__(self, "tag_id", check_int(self.tag_id, f"{where} tag id", lo=0))


@dataclass(frozen=True, eq=False)
class Recording:
    """A loaded recording bundle (a directory with recording.toml; docs/formats.md).

    Attributes
    ----------
    name : str
    markers : MarkerTrajectories or None
        On the mocap clock; None for a rigid robot known from its controller log and URDF only.
    controller : ControllerLog or None
        On the controller clock: t_controller = t_mocap + clock_offset_s; None for markers only
        (a passive hinge or a human joint: axes and angles, no deflection).
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
    markers: MarkerTrajectories | None
    controller: ControllerLog | None
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

    def __post_init__(self) -> None:
        if self.markers is None and self.controller is None and not self.markers_from_cameras:
            raise InputError(self.root, "recording", "a marker file, a controller log or both", "neither")
        object.__setattr__(self, "joints", tuple(self.joints))
        object.__setattr__(self, "clock_offset_s", check_scalar(self.clock_offset_s, "markers.clock_offset_s",
                                                                file=self.root))

    @property
    def markers_from_cameras(self) -> bool:
        """True for a bundle whose markers are still to be triangulated from its cameras' 2D
        detections (``[rig] clusters``, no ``[markers]``: docs/formats.md); ``mocapfj run`` does it."""
        rig = self.spec.get("rig") if isinstance(self.spec, Mapping) else None
        return self.markers is None and isinstance(rig, Mapping) and "clusters" in rig

    def joint(self, name: str) -> JointSpec:
        for j in self.joints:
            if j.name == name:
                return j
        raise InputError(self.root, "joints", f"one of {[j.name for j in self.joints]}", repr(name))

    def joint_index(self, name: str) -> int:
        """Position of joint `name` in `joints` (and in the controller log's columns)."""
        return self.joints.index(self.joint(name))

    def markers_t_controller(self) -> np.ndarray:
        """Mocap sample times on the controller clock, (T,) s."""
        if self.markers is None:
            raise InputError(self.root, "markers", "a recording with a marker file", "none")
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
        labels = tuple(str(s) for s in self.labels)
        dims = {"P": len(labels)}
        for name, shape in (("axis", (3,)), ("point", (3,)), ("template", ("P", 3)), ("radii", ("P",)),
                            ("radius_rms", ("P",)), ("cov_axis", (3, 3)), ("cov_point", (3, 3))):
            object.__setattr__(self, name, freeze(check_array(getattr(self, name), f"JointGeometry.{name}", shape,
                                                              dims=dims)))
        object.__setattr__(self, "labels", labels)
        object.__setattr__(self, "marker_rms", check_scalar(self.marker_rms, "JointGeometry.marker_rms", nonneg=True,
                                                            allow_nan=True))
        object.__setattr__(self, "sigma_m", check_scalar(self.sigma_m, "JointGeometry.sigma_m", nonneg=True,
                                                         allow_nan=True))
        object.__setattr__(self, "n_frames", check_int(self.n_frames, "JointGeometry.n_frames", lo=0))


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

    def __post_init__(self) -> None:
        dims = {}
        for name in ("t", "q", "sigma_q", "marker_rms"):
            object.__setattr__(self, name, freeze(check_array(getattr(self, name), f"JointAngles.{name}", ("T",),
                                                              dims=dims)))
        for name in ("n_markers", "n_rejected"):
            object.__setattr__(self, name, freeze(check_array(getattr(self, name), f"JointAngles.{name}", ("T",),
                                                              dims=dims, dtype=np.int64)))

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

    def __post_init__(self) -> None:
        dims = {}
        for name in ("t", "q", "q_m", "delta", "sigma_delta", "tau"):
            object.__setattr__(self, name, freeze(check_array(getattr(self, name), f"Deflection.{name}", ("T",),
                                                              dims=dims)))
        object.__setattr__(self, "q_offset_rad", check_scalar(self.q_offset_rad, "Deflection.q_offset_rad"))
        object.__setattr__(self, "q_m_quantum_rad", check_scalar(self.q_m_quantum_rad, "Deflection.q_m_quantum_rad",
                                                                 nonneg=True))


@dataclass(frozen=True, eq=False)
class LSResult:
    """A least-squares identification with its statistics (Jubien, Abba and Gautier (2014), eq. 15-17).

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

    def __post_init__(self) -> None:
        names = tuple(str(n) for n in self.names)
        dims = {"p": len(names)}
        for name, shape in (("values", ("p",)), ("std", ("p",)), ("rel_std_pct", ("p",)), ("cov", ("p", "p"))):
            object.__setattr__(self, name, freeze(check_array(getattr(self, name), f"LSResult.{name}", shape,
                                                              dims=dims)))
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "unidentifiable", tuple(self.unidentifiable))
        for name in ("cond", "residual_rms", "rel_error_pct", "r2"):
            object.__setattr__(self, name, check_scalar(getattr(self, name), f"LSResult.{name}", allow_nan=True))
        object.__setattr__(self, "n_samples", check_int(self.n_samples, "LSResult.n_samples", lo=0))

    def __getitem__(self, name: str) -> float:
        return float(self.values[self.names.index(name)])

    def std_of(self, name: str) -> float:
        """The standard deviation of parameter `name`."""
        return float(self.std[self.names.index(name)])


@dataclass(frozen=True, eq=False)
class JointSignals:
    """One joint's signals on one clock, ready for identification (docs/conventions.md).

    Attributes
    ----------
    t : (T,) float
        Sample times, s, uniform at `fs_hz` (the mocap samples on the controller clock).
    q : (T,) float
        Link angle from mocap, rad (zero aligned to the motor's by the mean deflection; short gaps
        filled by interpolation and counted in `n_filled`).
    q_m : (T,) float
        Motor angle / gear ratio, rad (link side), anti-aliased and interpolated at `t`.
    u : (T,) float
        Motor torque x gear ratio, N m (link side), anti-aliased and interpolated at `t`.
    fs_hz : float
        Sampling rate of `t`, Hz.
    n_filled : int
        Link-angle samples filled by interpolation across short gaps.
    name : str
        The joint.
    filled : (T,) bool or None
        True where the link angle was filled (not measured); None when none was (or unknown).
        Output-error identification leaves these samples out of the mocap comparison.
    t_c, q_m_c, u_c : (T_c,) float or None
        The controller's own samples over the same span, uniform at `fs_c_hz` (s on the same
        clock, rad, N m, link side), unfiltered: output-error identification compares the torque
        at this rate. None when only the mocap-clock signals are known.
    fs_c_hz : float or None
    smoothing_hz : float or None
        The corner of a low-pass the markers went through before export (the mocap software's
        smoothing), Hz, as their residuals show it (:func:`mocapfj.joints.smoothing.smoothing_corner_hz`);
        None when they were not smoothed or it is not known. The link angle carries nothing of the
        joint above it.
    """

    t: np.ndarray
    q: np.ndarray
    q_m: np.ndarray
    u: np.ndarray
    fs_hz: float
    n_filled: int = 0
    name: str = ""
    filled: np.ndarray | None = None
    t_c: np.ndarray | None = None
    q_m_c: np.ndarray | None = None
    u_c: np.ndarray | None = None
    fs_c_hz: float | None = None
    smoothing_hz: float | None = None

    def __post_init__(self) -> None:
        dims = {}
        for name in ("t", "q", "q_m", "u"):
            object.__setattr__(self, name, freeze(check_array(getattr(self, name), f"{self.name or 'signals'}: {name}",
                                                              ("T",), dims=dims, finite=True)))
        object.__setattr__(self, "fs_hz", check_scalar(self.fs_hz, "fs_hz", positive=True))
        object.__setattr__(self, "n_filled", check_int(self.n_filled, "n_filled", lo=0))
        if self.filled is not None:
            f = np.asarray(self.filled)
            if f.shape != self.t.shape or f.dtype != bool:
                raise InputError(None, f"{self.name or 'signals'}: filled", f"a (T,) = {self.t.shape} bool array",
                                 f"{f.shape} {f.dtype}")
            object.__setattr__(self, "filled", freeze(f.copy()))
        given = [x is not None for x in (self.t_c, self.q_m_c, self.u_c, self.fs_c_hz)]
        if any(given) and not all(given):
            raise InputError(None, f"{self.name or 'signals'}: t_c, q_m_c, u_c, fs_c_hz", "all four or none",
                             f"{sum(given)} of 4")
        if all(given):
            cdims = {}
            for name in ("t_c", "q_m_c", "u_c"):
                object.__setattr__(self, name, freeze(check_array(getattr(self, name), f"{self.name or 'signals'}: {name}",
                                                                  ("T_c",), dims=cdims, finite=True)))
            object.__setattr__(self, "fs_c_hz", check_scalar(self.fs_c_hz, "fs_c_hz", positive=True))
        if self.smoothing_hz is not None:
            object.__setattr__(self, "smoothing_hz", check_scalar(self.smoothing_hz, "smoothing_hz", positive=True))

    @property
    def has_controller_rate(self) -> bool:
        """True when the controller's own samples are attached (t_c, q_m_c, u_c)."""
        return self.t_c is not None

    @property
    def n_samples(self) -> int:
        return int(self.t.size)

    @property
    def measured(self) -> np.ndarray:
        """(T,) bool: True where the link angle was measured (not filled)."""
        return np.ones(self.t.size, bool) if self.filled is None else ~self.filled

    def head(self, n: int) -> "JointSignals":
        """The first `n` samples."""
        if n >= self.t.size:
            return self
        ctrl = {}
        if self.t_c is not None:
            keep = self.t_c <= self.t[n - 1] + 1.0 / self.fs_c_hz
            ctrl = dict(t_c=self.t_c[keep], q_m_c=self.q_m_c[keep], u_c=self.u_c[keep], fs_c_hz=self.fs_c_hz)
        return JointSignals(self.t[:n], self.q[:n], self.q_m[:n], self.u[:n], self.fs_hz,
                            int(self.n_filled if self.filled is None else self.filled[:n].sum()), self.name,
                            None if self.filled is None else self.filled[:n], **ctrl, smoothing_hz=self.smoothing_hz)
