"""One camera's intrinsics from views of a planar board, with their uncertainty.

The model is OpenCV's pinhole with distortion (:mod:`mocapfj.vision.camera`), fitted by
``cv2.calibrateCamera`` (Zhang 2000's closed-form start, then Levenberg-Marquardt over the
intrinsics and every view's pose). Around it:

- **Views** with fewer than 6 features, or features on one line, are left out and named.
- **Outliers.** A view whose RMS reprojection error is more than 3 times the median view's and
  whose chi-square (its squared residuals over the noise variance the other views give) is beyond
  the 0.999 quantile of its degrees of freedom is rejected, the worst first, and the fit redone;
  at most a third of the views go. Single features further than 6 noise SDs (and 1 px) from
  their reprojection are dropped the same way (a ChArUco corner at a marker's edge).
- **Uncertainty.** The covariance of the intrinsics is ``s^2 (J^T J)^-1`` restricted to them: the
  Gauss-Newton information of all parameters (intrinsics and the 6 pose parameters of every
  view, Jacobians from ``cv2.projectPoints``) with the poses eliminated by their Schur
  complement, and ``s^2 = SSR / (2 N - p)`` the per-coordinate noise variance with the degrees of
  freedom corrected for the p fitted parameters. Checked against the truth on synthetic views
  (tests/vision/test_intrinsics.py; benchmarks/bench_intrinsics_uncertainty.py): the mean squared
  z-score of fx, fy, cx, cy and the distortion over many seeds and geometries is about 1.
- **Degenerate views.** When every view shows the board from nearly one direction the focal
  length is not determined (Zhang 2000, section 3.3: parallel planes add no constraint); a fit
  whose fx or fy has an SD above 5 % is refused with an error naming the views and the spread
  of their board normals, never returned as a number (at 0.3 px of noise, ten views tilted by
  0.5 deg give an SD of 30 %, by 2 deg 11 %, by 5 deg 2 %, by 10 deg 0.7 %); above 1 % it is a
  warning.
- **Coverage**: how many features fell in each cell of a grid over the image (the corners of
  the image are where the distortion is least constrained).

Pixels follow docs/conventions.md (0-based pixel centres). A view's pose maps board into camera
coordinates: ``p_cam = R(rvec) p_board + tvec`` (metres).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy import stats

from ..errors import InputError
from ..types import Board, Camera
from .boards import BoardDetection, board_points

__all__ = ["MODELS", "ViewFit", "Intrinsics", "calibrate_intrinsics"]

MODELS = {
    "standard": ("k1", "k2", "p1", "p2", "k3"),
    "no_k3": ("k1", "k2", "p1", "p2"),
    "rational": ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
}
"""Distortion models: the OpenCV coefficients each fits (``no_k3`` is Bouguet's toolbox default)."""

_FLAGS = {"standard": 0, "no_k3": cv2.CALIB_FIX_K3, "rational": cv2.CALIB_RATIONAL_MODEL}
MIN_VIEW_POINTS = 6
MIN_VIEWS = 3
MAX_FOCAL_REL_SD = 0.05
WARN_FOCAL_REL_SD = 0.01
_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)


@dataclass(frozen=True, eq=False)
class ViewFit:
    """One view in the calibration.

    Attributes
    ----------
    name : str
    status : {"used", "rejected", "no board", "too few points"}
    n_points : int
        Features detected (used: those fitted).
    rms_px : float
        RMS reprojection error of its features, pixels (also for a rejected view, at the fit
        that rejected it); NaN when not fitted.
    reason : str
        Why it was not used ("" when used).
    rvec, tvec : (3,) float
        Board pose in the camera (``p_cam = R(rvec) p_board + tvec``, rad and metres); NaN when not used.
    """

    name: str
    status: str
    n_points: int
    rms_px: float
    reason: str = ""
    rvec: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    tvec: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))

    def to_dict(self) -> dict:
        out = {"name": self.name, "status": self.status, "n_points": self.n_points,
               "rms_px": None if not np.isfinite(self.rms_px) else float(self.rms_px)}
        if self.reason:
            out["reason"] = self.reason
        return out


@dataclass(frozen=True, eq=False)
class Intrinsics:
    """A camera's intrinsics from board views (`calibrate_intrinsics`).

    Attributes
    ----------
    camera : Camera
        K and distortion; identity extrinsics.
    model : str
        Key of `MODELS`.
    rms_px : float
        RMS reprojection error over the features used, pixels (per feature: the distance).
    sigma_px : float
        Noise SD per image coordinate estimated from the residuals, pixels.
    param_names : tuple of str
        ``fx, fy, cx, cy`` and the model's distortion coefficients.
    values, std : (p,) float
        The parameters and their standard deviations.
    covariance : (p, p) float
    views : tuple of ViewFit
        Every input view, in input order.
    n_points : int
        Features used.
    n_points_rejected : int
        Features dropped as outliers from the views used.
    coverage : (rows, cols) int
        Features used per cell of a grid over the image (cells about 1/10 of the width).
    coverage_pct : float
        Share of cells with at least one feature, %.
    points_px, residuals_px : (n_points, 2) float
        The features used and their reprojection residuals (measured - model), pixels.
    warnings : tuple of str
    """

    camera: Camera
    model: str
    rms_px: float
    sigma_px: float
    param_names: tuple
    values: np.ndarray
    std: np.ndarray
    covariance: np.ndarray
    views: tuple
    n_points: int
    n_points_rejected: int
    coverage: np.ndarray
    coverage_pct: float
    points_px: np.ndarray
    residuals_px: np.ndarray
    warnings: tuple = ()

    @property
    def n_views(self) -> int:
        return len(self.views)

    @property
    def n_views_used(self) -> int:
        return sum(v.status == "used" for v in self.views)

    @property
    def std_by_name(self) -> dict:
        return {n: float(s) for n, s in zip(self.param_names, self.std)}

    def to_dict(self) -> dict:
        K = self.camera.K
        return {
            "fx": float(K[0, 0]), "fy": float(K[1, 1]), "cx": float(K[0, 2]), "cy": float(K[1, 2]),
            "dist": self.camera.dist.tolist(),
            "model": self.model,
            "dist_names": list(MODELS[self.model]),
            "image_size": list(self.camera.size),
            "rms_px": float(self.rms_px),
            "sigma_px": float(self.sigma_px),
            "n_views_used": self.n_views_used,
            "n_views": self.n_views,
            "n_points": self.n_points,
            "n_points_rejected": self.n_points_rejected,
            "std": self.std_by_name,
            "coverage_pct": float(self.coverage_pct),
            "views": [v.to_dict() for v in self.views],
            "warnings": list(self.warnings),
        }


def _collinear(p_board: np.ndarray) -> bool:
    q = p_board[:, :2] - p_board[:, :2].mean(axis=0)
    s = np.linalg.svd(q, compute_uv=False)
    return len(s) < 2 or s[1] < 1e-6 * max(s[0], 1e-12)


def _fit(obj, img, size, model, K0=None, d0=None):
    flags = _FLAGS[model]
    if K0 is not None:
        flags |= cv2.CALIB_USE_INTRINSIC_GUESS
    try:
        rms, K, d, rv, tv = cv2.calibrateCamera([o.astype(np.float32) for o in obj],
                                                [i.astype(np.float32) for i in img], size,
                                                None if K0 is None else K0.copy(),
                                                None if d0 is None else d0.copy(), flags=flags, criteria=_CRITERIA)
    except cv2.error as e:
        return None, " ".join(str(e).split())[-160:]
    if not (np.isfinite(K).all() and np.isfinite(d).all()):
        return None, "the fit diverged"
    n = len(MODELS[model])
    return (K, d.ravel()[: max(n, 5)], [r.ravel() for r in rv], [t.ravel() for t in tv]), ""


def _project(obj, rvec, tvec, K, d):
    x, jac = cv2.projectPoints(obj.astype(np.float64), rvec, tvec, K, d)
    return x.reshape(-1, 2), jac


def _residuals_and_info(obj, img, sol, model):
    """Residuals per view and the Schur-complement information of the intrinsics."""
    K, d, rvs, tvs = sol
    n_dist = len(MODELS[model])
    res, info = [], None
    for o, i, rv, tv in zip(obj, img, rvs, tvs):
        x, jac = _project(o, rv, tv, K, d)
        res.append(i - x)
        je = jac[:, :6]                                          # pose: rvec, tvec
        ji = jac[:, 6:10 + n_dist]                               # fx, fy, cx, cy, distortion
        a = ji.T @ ji
        b = ji.T @ je
        c = je.T @ je
        s = a - b @ np.linalg.solve(c, b.T)
        info = s if info is None else info + s
    return res, info


def _view_normal_spread_deg(rvs) -> float:
    n = np.array([cv2.Rodrigues(np.asarray(r, float))[0][:, 2] for r in rvs])
    cosang = np.clip(n @ n.T, -1.0, 1.0)
    return float(np.degrees(np.arccos(cosang)).max())


def calibrate_intrinsics(detections: Sequence[BoardDetection | None], board: Board, *,
                         names: Sequence[str] | None = None, model: str = "standard",
                         reject_outliers: bool = True, camera_name: str = "cam_0",
                         coverage_cells: int = 10) -> Intrinsics:
    """Calibrate one camera from detections of `board` (module docstring).

    Parameters
    ----------
    detections : sequence of BoardDetection or None
        One per view (None: no board found in it), all from images of one size.
    board : Board
    names : sequence of str, optional
        View names for messages and the report (default ``view0``, ``view1``, ...).
    model : {"standard", "no_k3", "rational"}
        Distortion coefficients to fit (`MODELS`).
    reject_outliers : bool
        Reject outlier views and features (module docstring).
    camera_name : str
        Name of the returned camera.
    coverage_cells : int
        Grid cells across the image's width for the coverage map.

    Returns
    -------
    Intrinsics

    Raises
    ------
    InputError
        Fewer than 3 usable views (naming those without a board), images of different sizes,
        a fit that fails or diverges, or a focal length the views do not determine (naming them).
    """
    if model not in MODELS:
        raise InputError(None, "model", f"one of {list(MODELS)}", repr(model))
    dets = list(detections)
    names = [f"view{k}" for k in range(len(dets))] if names is None else [str(n) for n in names]
    if len(names) != len(dets):
        raise InputError(None, "names", f"{len(dets)} names (one per detection)", len(names))
    ids_all, p_board = board_points(board)
    index = {int(k): n for n, k in enumerate(ids_all)}
    sizes = {tuple(d.image_size) for d in dets if d is not None}
    if len(sizes) > 1:
        by = {s: [n for n, d in zip(names, dets) if d is not None and tuple(d.image_size) == s] for s in sizes}
        raise InputError(names[0], "image size", "one image size for one camera",
                         "; ".join(f"{s[0]}x{s[1]}: {', '.join(v[:3])}" for s, v in by.items()))
    views: list[ViewFit | None] = [None] * len(dets)
    obj, img, where = [], [], []
    for k, (name, d) in enumerate(zip(names, dets)):
        if d is None:
            views[k] = ViewFit(name, "no board", 0, np.nan, "the board was not found")
            continue
        unknown = [int(i) for i in d.ids if int(i) not in index]
        if unknown:
            raise InputError(name, "feature ids", f"ids of the board ({len(ids_all)} features)", unknown[:5])
        o = p_board[[index[int(i)] for i in d.ids]]
        if len(d.ids) < MIN_VIEW_POINTS or _collinear(o):
            views[k] = ViewFit(name, "too few points", len(d.ids), np.nan,
                               f"{len(d.ids)} features" + (" on one line" if len(d.ids) >= MIN_VIEW_POINTS else
                                                          f" (at least {MIN_VIEW_POINTS} needed)"))
            continue
        obj.append(o)
        img.append(np.asarray(d.xy_px, dtype=np.float64))
        where.append(k)
    missing = [names[k] for k in range(len(dets)) if views[k] is not None]
    if len(obj) < MIN_VIEWS:
        raise InputError(names[0] if len(names) == 1 else f"{len(names)} views", "board views",
                         f"at least {MIN_VIEWS} views showing the {board.type} (Zhang 2000)",
                         f"{len(obj)} usable" + (f"; not usable: {_name_list(missing)}" if missing else ""),
                         hint=None if obj else "check the board file (type, columns x rows, dictionary) against the print")
    size = sizes.pop()
    keep_pts = [np.ones(len(o), bool) for o in obj]
    active = list(range(len(obj)))
    rejected: dict[int, tuple[float, str]] = {}
    warnings: list[str] = []
    sol = None
    for _ in range(len(obj) + 5):
        o_act = [obj[v][keep_pts[v]] for v in active]
        i_act = [img[v][keep_pts[v]] for v in active]
        sol, why = _fit(o_act, i_act, size, model)
        if sol is None:
            raise InputError(_name_list([names[where[v]] for v in active]), "calibration",
                             "views from which cv2.calibrateCamera converges", why)
        res, _ = _residuals_and_info(o_act, i_act, sol, model)
        if not reject_outliers:
            break
        sq = [np.sum(r * r) for r in res]
        npts = np.array([len(r) for r in res])
        view_rms = np.sqrt(np.array(sq) / npts)
        var = np.median(np.array(sq) / (2 * npts))                     # robust per-coordinate variance
        far = [np.linalg.norm(r, axis=1) > max(6.0 * np.sqrt(var), 1.0) for r in res]
        frac = np.array([f.mean() for f in far])
        can_drop = len(rejected) + 1 <= len(obj) // 3 and len(active) - 1 >= MIN_VIEWS
        if frac.max() > 0.2 and can_drop:                 # many features off: the view is wrong
            worst = int(np.argmax(frac + 1e-6 * view_rms))
            why = f"outlier: {100 * frac[worst]:.0f} % of its features more than 6 noise SDs off, RMS {view_rms[worst]:.3g} px"
        else:
            changed = False                               # a few features off: drop those
            for v, f in zip(active, far):
                if f.any() and (len(f) - f.sum()) >= MIN_VIEW_POINTS:
                    keep_pts[v][np.nonzero(keep_pts[v])[0][f]] = False
                    changed = True
            if changed:
                continue
            chi2 = np.array(sq) / var
            limit = stats.chi2.ppf(0.999, np.maximum(2 * npts - 6, 1))
            out = (view_rms > 3.0 * np.median(view_rms)) & (chi2 > limit)
            if not out.any() or not can_drop:
                break
            worst = int(np.argmax(np.where(out, view_rms, -1.0)))
            why = f"outlier: RMS {view_rms[worst]:.3g} px, {view_rms[worst] / np.median(view_rms):.1f} x the median view's"
        v = active.pop(worst)
        rejected[v] = (float(view_rms[worst]), why)
    o_act = [obj[v][keep_pts[v]] for v in active]
    i_act = [img[v][keep_pts[v]] for v in active]
    res, info = _residuals_and_info(o_act, i_act, sol, model)
    K, d, rvs, tvs = sol
    n_dist = len(MODELS[model])
    n_pts = int(sum(len(r) for r in res))
    ssr = float(sum(np.sum(r * r) for r in res))
    free = 4 + n_dist
    dof = 2 * n_pts - free - 6 * len(active)
    if dof <= 0:
        raise InputError(_name_list([names[where[v]] for v in active]), "board views",
                         "more features than parameters", f"{n_pts} features for {free + 6 * len(active)} parameters")
    var = ssr / dof
    param_names = ("fx", "fy", "cx", "cy") + MODELS[model]
    try:
        cov = var * np.linalg.inv(info)
    except np.linalg.LinAlgError:
        cov = np.full(info.shape, np.inf)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, np.inf))
    sd[~np.isfinite(sd)] = np.inf
    dist = d[:n_dist]
    values = np.concatenate([[K[0, 0], K[1, 1], K[0, 2], K[1, 2]], dist])
    used_names = [names[where[v]] for v in active]
    rel = max(sd[0] / values[0], sd[1] / values[1])
    if not np.isfinite(values).all() or not rel <= MAX_FOCAL_REL_SD:
        spread = _view_normal_spread_deg(rvs)
        raise InputError(_name_list(used_names), "board views",
                         f"views that determine the focal length (SD of fx, fy under {100 * MAX_FOCAL_REL_SD:g} %)",
                         f"SD {100 * rel:.3g} % with the board's normal within {spread:.1f} deg across the "
                         f"{len(active)} views", hint="tilt the board by 20-45 deg in some views, in different directions")
    if rel > WARN_FOCAL_REL_SD:
        warnings.append(f"focal length poorly determined (SD {100 * rel:.2g} %): the board's normal varies by "
                        f"{_view_normal_spread_deg(rvs):.0f} deg over the views and covers {_coverage_pct(i_act, size):.0f} % "
                        "of the image; add views tilted 20-45 deg and near the image's edges")
    for v, (rms_v, why) in rejected.items():
        warnings.append(f"view {names[where[v]]} rejected ({why})")
    n_dropped = int(sum((~keep_pts[v]).sum() for v in active))
    if n_dropped:
        warnings.append(f"{n_dropped} features further than 6 noise SDs from their reprojection dropped")
    no_board = [names[k] for k in range(len(dets)) if views[k] is not None and views[k].status == "no board"]
    if no_board:
        warnings.append(f"no board found in {len(no_board)} of {len(dets)} views: {_name_list(no_board)}")
    for pos, v in enumerate(active):
        r = res[pos]
        views[where[v]] = ViewFit(names[where[v]], "used", len(r), float(np.sqrt(np.mean(np.sum(r * r, axis=1)))),
                                  "", np.asarray(rvs[pos], float), np.asarray(tvs[pos], float))
    for v, (rms_v, why) in rejected.items():
        views[where[v]] = ViewFit(names[where[v]], "rejected", len(obj[v]), rms_v, why)
    pts = np.concatenate(i_act)
    resid = np.concatenate(res)
    cov_grid = _coverage(pts, size, coverage_cells)
    cam = Camera(camera_name, size, np.array([[values[0], 0.0, values[2]], [0.0, values[1], values[3]], [0, 0, 1.0]]),
                 dist, np.eye(3), np.zeros(3))
    return Intrinsics(camera=cam, model=model, rms_px=float(np.sqrt(ssr / n_pts)), sigma_px=float(np.sqrt(var)),
                      param_names=param_names, values=values, std=sd, covariance=cov, views=tuple(views),
                      n_points=n_pts, n_points_rejected=n_dropped, coverage=cov_grid.astype(np.int64),
                      coverage_pct=float(100.0 * (cov_grid > 0).mean()), points_px=pts, residuals_px=resid,
                      warnings=tuple(warnings))


def _coverage(pts: np.ndarray, size, cells: int = 10) -> np.ndarray:
    """Features per cell of a grid `cells` wide over an image of `size` (width, height), (rows, cols)."""
    w, h = size
    gy = max(1, int(round(cells * h / w)))
    grid, _, _ = np.histogram2d(pts[:, 1], pts[:, 0], bins=(gy, int(cells)), range=((-0.5, h - 0.5), (-0.5, w - 0.5)))
    return grid


def _coverage_pct(img: Sequence[np.ndarray], size) -> float:
    return float(100.0 * (_coverage(np.concatenate(img), size) > 0).mean())


def _name_list(names: Sequence[str], limit: int = 6) -> str:
    names = list(names)
    return ", ".join(names[:limit]) + (f" and {len(names) - limit} more" if len(names) > limit else "")
