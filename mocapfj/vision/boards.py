"""Calibration targets (``calibration/boards/*.toml``): their feature points, and finding them in
an image with sub-pixel accuracy.

Targets (docs/formats.md, docs/calibration.md):

- **chessboard**: ``columns`` x ``rows`` inner corners, ``square_m``. Found by a lattice grown
  from saddle points (:mod:`mocapfj.vision.lattice`; it follows strong distortion and blur), else
  OpenCV's classic detector, else its sector-based detector (Duda and Frese 2018), and in every
  case placed to sub-pixel by point symmetry. The whole board must be seen (a partial chessboard
  has no way to say which corners it shows).
- **charuco**: ``columns`` x ``rows`` squares with ArUco markers (``dictionary``, ``marker_m``);
  partial views are fine (the markers name the corners). ``inverted = true`` boards (printed
  white on black) are found in the inverted grey image.
- **aprilgrid** (Kalibr style): ``columns`` x ``rows`` AprilTags of side ``tag_m`` with gaps of
  ``spacing_m``, tag id ``row * columns + column`` from the top-left; partial views are fine.
  Tag corners are refined as intersections of the tag's edges (each fitted by a quadratic curve
  along the side), which blur does not shift.

Feature ids (`board_points`): chessboard ``j * columns + i`` for inner corner (i, j); charuco
OpenCV's charuco corner id (the same numbering); aprilgrid ``4 * tag + k`` with k = 0..3 the tag's
top-left, top-right, bottom-right and bottom-left corners.

Orientation. A chessboard's squares tell its orientation only when the board is not symmetric:
with ``columns + rows`` odd (e.g. 9 x 6) a half turn swaps the black and white squares, so the
detector orders the corners so that the outer square beyond corner 0 is black (as
:func:`mocapfj.synth.images.board_texture` prints it). With ``columns + rows`` even (8 x 6, 7 x 5)
a half turn maps the board onto itself, and a square board (n x n) also a quarter turn: then
corner 0 is put at the end nearest to the image's top-left (smallest x + y), which two cameras
seeing the board from similar directions agree on, but not in general. `board_symmetry` says how
many orientations a board cannot tell apart; a multi-camera calibration must resolve them (or use
an asymmetric board, a ChArUco board or an AprilGrid). One camera's intrinsics do not depend on it.

Frames and pixels follow docs/conventions.md: board frame origin at the top-left corner of the
printed pattern, x along the columns, y down the rows, z into the board; pixel centres 0-based.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial import cKDTree

from ..errors import InputError
from ..types import BOARD_TYPES, Board
from .corners import refine_saddles, refine_square_corners, saddle_points, xjunction_test
from .lattice import grow_lattice, lattice_size, lattice_spacing, predict_nodes

__all__ = ["BoardDetection", "APRILTAG_DICTIONARIES", "aruco_dictionary", "charuco_board", "board_points",
           "board_symmetry", "grey_image", "detect_board", "chessboard_size"]

APRILTAG_DICTIONARIES = {"tag36h11": "DICT_APRILTAG_36h11", "tag25h9": "DICT_APRILTAG_25h9",
                         "tag16h5": "DICT_APRILTAG_16h5", "tag36h10": "DICT_APRILTAG_36h10"}
"""AprilTag families and the OpenCV dictionaries that hold them."""

_MIN_POINTS = 4          # fewer features than this are not a detection (no homography, no pose)


@dataclass(frozen=True, eq=False)
class BoardDetection:
    """One view of one board.

    Attributes
    ----------
    ids : (n,) int
        Feature ids, numbered as `board_points` numbers them, ascending.
    xy_px : (n, 2) float64
        Sub-pixel positions, pixels (0-based pixel centres, docs/conventions.md).
    image_size : (width, height) int
    method : str
        The detector that found it: ``"grow"``, ``"classic"``, ``"sb"`` (chessboard), ``"charuco"``
        or ``"aprilgrid"``.
    """

    ids: np.ndarray
    xy_px: np.ndarray
    image_size: tuple[int, int]
    method: str

    def __post_init__(self) -> None:
        ids = np.asarray(self.ids, dtype=np.int64).ravel()
        xy = np.asarray(self.xy_px, dtype=np.float64).reshape(-1, 2)
        if len(ids) != len(xy):
            raise InputError(None, "BoardDetection", "as many ids as points", f"{len(ids)} ids, {len(xy)} points")
        ids.setflags(write=False)
        xy.setflags(write=False)
        object.__setattr__(self, "ids", ids)
        object.__setattr__(self, "xy_px", xy)
        object.__setattr__(self, "image_size", (int(self.image_size[0]), int(self.image_size[1])))

    def to_dict(self) -> dict:
        return {"ids": self.ids.tolist(), "xy_px": self.xy_px.tolist(), "image_size": list(self.image_size),
                "method": self.method}


def _check_board(board: Board) -> None:
    if not isinstance(board, Board) or board.type not in BOARD_TYPES:
        raise InputError(None, "board", f"a Board of type {list(BOARD_TYPES)}", getattr(board, "type", board))
    need = {"chessboard": ("square_m",), "charuco": ("square_m", "marker_m", "dictionary"),
            "aprilgrid": ("tag_m", "spacing_m", "family")}[board.type]
    for key in need:
        if getattr(board, key) is None:
            raise InputError(None, f"board.{key}", f"a value (required for a {board.type})", "None")
    if board.type == "charuco" and not board.marker_m < board.square_m:
        raise InputError(None, "board.marker_m", f"less than square_m ({board.square_m})", board.marker_m)


def aruco_dictionary(board: Board):
    """The OpenCV ArUco dictionary of a charuco board (``dictionary``) or an aprilgrid (``family``)."""
    name = board.dictionary if board.type == "charuco" else APRILTAG_DICTIONARIES.get(board.family or "",
                                                                                      board.dictionary)
    if not name or not str(name).startswith("DICT_") or not hasattr(cv2.aruco, str(name)):
        raise InputError(None, "board.dictionary" if board.type == "charuco" else "board.family",
                         "an OpenCV ArUco dictionary (DICT_4X4_50 ...) or an AprilTag family "
                         f"({', '.join(APRILTAG_DICTIONARIES)})",
                         board.dictionary if board.type == "charuco" else board.family)
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, str(name)))


def charuco_board(board: Board, legacy: bool = False):
    """The ``cv2.aruco.CharucoBoard`` of a charuco `board` (legacy: OpenCV < 4.6's layout)."""
    cb = cv2.aruco.CharucoBoard((board.columns, board.rows), board.square_m, board.marker_m, aruco_dictionary(board))
    if legacy:
        cb.setLegacyPattern(True)
    return cb


def board_points(board: Board) -> tuple[np.ndarray, np.ndarray]:
    """The feature points of `board` in its frame.

    Returns
    -------
    ids : (N,) int
        chessboard: j * columns + i for inner corner (i, j); charuco: OpenCV's charuco corner
        id; aprilgrid: 4 * tag_id + k with k = 0..3 the tag corners top-left, top-right,
        bottom-right, bottom-left (ArUco order), tag_id = row * columns + column.
    p_board : (N, 3) float
        Positions in the board frame, metres (z = 0).
    """
    _check_board(board)
    if board.type == "chessboard":
        j, i = np.mgrid[0:board.rows, 0:board.columns]
        xy = np.stack([(i.ravel() + 1) * board.square_m, (j.ravel() + 1) * board.square_m], axis=1)
        ids = np.arange(board.rows * board.columns)
    elif board.type == "charuco":
        p = np.asarray(charuco_board(board).getChessboardCorners(), dtype=np.float64)
        return np.arange(len(p)), p
    else:
        pitch = board.tag_m + board.spacing_m
        j, i = np.mgrid[0:board.rows, 0:board.columns]
        tl = np.stack([i.ravel() * pitch, j.ravel() * pitch], axis=1)                      # (n_tags, 2)
        k = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=np.float64) * board.tag_m
        xy = (tl[:, None, :] + k[None]).reshape(-1, 2)
        ids = np.arange(len(xy))
    return ids, np.concatenate([xy, np.zeros((len(xy), 1))], axis=1)


def board_symmetry(board: Board) -> int:
    """How many orientations of `board` its detection cannot tell apart (1 = none; module docstring).

    A chessboard with ``columns + rows`` even: 2 (a half turn); a square one (n x n): 4 when n is
    even, 2 when n is odd. ChArUco boards and AprilGrids: 1 (their markers carry ids).
    """
    _check_board(board)
    if board.type != "chessboard":
        return 1
    if board.columns == board.rows:
        return 4 if board.columns % 2 == 0 else 2
    return 2 if (board.columns + board.rows) % 2 == 0 else 1


def grey_image(image, where: str | None = None) -> np.ndarray:
    """`image` as a 2-D uint8 grey image.

    Parameters
    ----------
    image : (H, W) or (H, W, 3|4) array
        uint8 or uint16 (scaled by its maximum), or float in [0, 1]; colour images are BGR(A)
        as OpenCV reads them.
    where : str, optional
        The file the image came from, for error messages.
    """
    a = np.asarray(image)
    if a.ndim == 3 and a.shape[2] in (3, 4):
        if a.dtype not in (np.uint8, np.uint16):
            a = np.clip(a * 255.0, 0, 255).astype(np.uint8)
        a = cv2.cvtColor(a, cv2.COLOR_BGR2GRAY if a.shape[2] == 3 else cv2.COLOR_BGRA2GRAY)
    if a.ndim != 2 or min(a.shape) < 8:
        raise InputError(where, "image", "a grey (H, W) or colour (H, W, 3) image at least 8 px a side",
                         f"shape {a.shape}")
    if a.dtype == np.uint8:
        return a
    if a.dtype == np.uint16:
        return (a.astype(np.float64) * (255.0 / max(int(a.max()), 1))).round().astype(np.uint8)
    if np.issubdtype(a.dtype, np.floating) and np.isfinite(a).all():
        return np.clip(np.rint(a * 255.0), 0, 255).astype(np.uint8)
    raise InputError(where, "image", "uint8, uint16 or finite float pixels", str(a.dtype))


def detect_board(image, board: Board) -> BoardDetection | None:
    """Find `board` in `image` with sub-pixel feature positions (module docstring).

    Parameters
    ----------
    image : (H, W) or (H, W, 3) array
        Grey or BGR image (`grey_image`).
    board : Board

    Returns
    -------
    BoardDetection, or None when the board is not in the image (a chessboard: not whole; a
    ChArUco board or an AprilGrid: fewer than 4 features).
    """
    _check_board(board)
    grey = grey_image(image)
    if board.inverted:
        grey = 255 - grey
    size = (grey.shape[1], grey.shape[0])
    if board.type == "chessboard":
        found = _detect_chessboard(grey, board)
    elif board.type == "charuco":
        found = _detect_charuco(grey, board)
    else:
        found = _detect_aprilgrid(grey, board)
    if found is None:
        return None
    ids, xy, method = found
    order = np.argsort(ids)
    return BoardDetection(ids=ids[order], xy_px=xy[order], image_size=size, method=method)


def chessboard_size(image) -> tuple[int, int] | None:
    """Inner corners (longer side first) of the largest chessboard-like lattice in `image`, or
    None: for saying what a board file should hold when a chessboard is not found."""
    return lattice_size(grey_image(image))


# --- chessboard ---------------------------------------------------------------------------------

def _classic(grey: np.ndarray, cols: int, rows: int) -> np.ndarray | None:
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
    ok, c = cv2.findChessboardCorners(grey, (cols, rows), flags=flags)
    return c.reshape(rows, cols, 2).astype(np.float64) if ok else None


def _sector_based(grey: np.ndarray, cols: int, rows: int) -> np.ndarray | None:
    flags = cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
    ok, c = cv2.findChessboardCornersSB(grey, (cols, rows), flags=flags)
    return c.reshape(rows, cols, 2).astype(np.float64) if ok else None


def _detect_chessboard(grey: np.ndarray, board: Board):
    cols, rows = board.columns, board.rows
    points = saddle_points(grey)
    stats: dict = {}

    def sector_based():
        # it costs about a second per megapixel: only where most of a board grew, not a larger one
        # and not one the image's edge cuts (no detector finds a chessboard that is not whole)
        xy = stats["best_xy"]
        if stats["best"] < 0.75 * cols * rows or stats["larger"] or len(xy) < 2:
            return None
        step = np.median(cKDTree(xy).query(xy, k=2)[0][:, 1])
        h, w = grey.shape
        if min(xy[:, 0].min(), xy[:, 1].min(), w - 1 - xy[:, 0].max(), h - 1 - xy[:, 1].max()) < 1.5 * step:
            return None
        return _sector_based(grey, cols, rows)

    tries = [("grow", lambda: grow_lattice(grey, cols, rows, points=points, stats=stats)),
             ("classic", lambda: _classic(grey, cols, rows)), ("sb", sector_based)]
    for method, find in tries:
        grid = find()
        if grid is None:
            continue
        xy = _finish_chessboard(grey, grid, board)
        if xy is not None:
            return np.arange(cols * rows), xy, method
    return None


def _cell_contrast(grey: np.ndarray, grid: np.ndarray) -> float:
    """Mean grey of the cells (i + j even) between the lattice's nodes minus that of the others."""
    c = 0.25 * (grid[:-1, :-1] + grid[:-1, 1:] + grid[1:, :-1] + grid[1:, 1:])     # cell centres
    j, i = np.indices(c.shape[:2])
    smooth = cv2.GaussianBlur(grey.astype(np.float32), (0, 0), 1.0)
    v = cv2.remap(smooth, c[..., 0].astype(np.float32), c[..., 1].astype(np.float32), cv2.INTER_LINEAR,
                  borderMode=cv2.BORDER_REPLICATE)
    even = (i + j) % 2 == 0
    return float(v[even].mean() - v[~even].mean())


def _orient_chessboard(grey: np.ndarray, grid: np.ndarray, board: Board) -> np.ndarray:
    """Order a (rows, cols, 2) lattice as the board numbers its corners (module docstring)."""
    a = grid[:, 1:] - grid[:, :-1]
    b = grid[1:] - grid[:-1]
    if (a[:-1, :, 0] * b[:, :-1, 1] - a[:-1, :, 1] * b[:, :-1, 0]).sum() < 0:
        grid = grid[:, ::-1]                      # mirrored: the board's x runs the other way
    cands = [grid, grid[::-1, ::-1]]
    if board.columns == board.rows:              # quarter turns keep a square lattice's shape
        cands += [np.rot90(grid, 1), np.rot90(grid, 3)]
    # inner cell (i, j) is board square (i + 1, j + 1): black when i + j is even
    dark = [g for g in cands if _cell_contrast(grey, g) < 0] or cands
    return min(dark, key=lambda g: g[0, 0].sum())


def _inconsistent(ij: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Points that do not fit their neighbours: the leave-one-out error against the homography of
    the points within one square (board grid units `ij`; two where one square holds too few), or
    against a quadratic extrapolation along its row or column when that is nearer, above 0.25 of
    the local spacing where the point is surrounded (interpolated), above 0.5 at the edge of what
    was seen (extrapolated, which strong distortion bends). A misassembled lattice is off by about
    one spacing."""
    q, ok = predict_nodes(ij, ij, xy, reach=1)
    far = ~ok
    if far.any():
        q2, ok2 = predict_nodes(ij[far], ij, xy, reach=2)
        q[far], ok[far] = q2, ok2
    spacing = np.minimum(np.linalg.norm(q[:, 1] - q[:, 0], axis=1), np.linalg.norm(q[:, 2] - q[:, 0], axis=1))
    err = np.linalg.norm(q[:, 0] - xy, axis=1)
    r = np.rint(ij).astype(np.int64)
    known = set(map(tuple, r.tolist()))
    at = {k: n for n, k in enumerate(map(tuple, r.tolist()))}
    for n, (i, j) in enumerate(r.tolist()):      # or a quadratic along its row or column, which bends
        for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            back = [at.get((i - m * di, j - m * dj)) for m in (1, 2, 3)]
            if None not in back:
                e = 3.0 * xy[back[0]] - 3.0 * xy[back[1]] + xy[back[2]]
                err[n] = min(err[n], np.linalg.norm(e - xy[n]))
    inside = np.array([all(n in known for n in ((i - 1, j), (i + 1, j), (i, j - 1), (i, j + 1))) for i, j in r.tolist()],
                      dtype=bool)
    with np.errstate(invalid="ignore"):
        return ok & (err > np.where(inside, 0.25, 0.5) * spacing)


def _finish_chessboard(grey: np.ndarray, grid: np.ndarray, board: Board) -> np.ndarray | None:
    """Sub-pixel positions of an assembled lattice, oriented and checked; None if it is not a board."""
    if not np.isfinite(grid).all():
        return None
    radius = np.clip(0.2 * lattice_spacing(grid).ravel(), 3.0, 8.0)
    xy, ok = refine_saddles(grey, grid.reshape(-1, 2), radius)
    if not ok.all():                                   # again with the smallest disc, else not a board
        xy[~ok], ok[~ok] = refine_saddles(grey, grid.reshape(-1, 2)[~ok], 3.0)
        if not ok.all():
            return None
    grid = _orient_chessboard(grey, xy.reshape(grid.shape), board)
    j, i = np.mgrid[0:board.rows, 0:board.columns]
    ij = np.stack([i.ravel(), j.ravel()], 1).astype(np.float64)
    if _inconsistent(ij, grid.reshape(-1, 2)).any() or _continues(grey, ij, grid.reshape(-1, 2), board):
        return None
    return grid.reshape(-1, 2)


def _continues(grey: np.ndarray, ij: np.ndarray, xy: np.ndarray, board: Board) -> bool:
    """True when the lattice goes on past a side of the board: more X-junctions one step beyond
    it (the printed board has more corners than `board` says; which ones were found is then unknown)."""
    c, r = board.columns, board.rows
    sides = [[(-1, j) for j in range(r)], [(c, j) for j in range(r)], [(i, -1) for i in range(c)], [(i, r) for i in range(c)]]
    ring = np.array([n for side in sides for n in side], dtype=np.float64)
    q, ok = predict_nodes(ring, ij, xy)
    h, w = grey.shape
    inside = ok & (q[:, 0, 0] > 3) & (q[:, 0, 1] > 3) & (q[:, 0, 0] < w - 4) & (q[:, 0, 1] < h - 4)
    if not inside.any():
        return False
    spacing = np.minimum(np.linalg.norm(q[:, 1] - q[:, 0], axis=1), np.linalg.norm(q[:, 2] - q[:, 0], axis=1))
    radius = np.clip(0.2 * np.nan_to_num(spacing, nan=15.0), 3.0, 8.0)
    found = np.zeros(len(ring), bool)
    pr = np.full((len(ring), 2), np.nan)
    conv = np.zeros(len(ring), bool)
    pr[inside], conv[inside] = refine_saddles(grey, q[inside, 0], radius[inside])
    light = cv2.GaussianBlur(grey.astype(np.float32), (0, 0), 0.7)
    start = 0
    for side in sides:
        sl = slice(start, start + len(side))
        start += len(side)
        sel = np.nonzero(conv[sl])[0] + sl.start
        if len(sel) < max(2, 0.5 * len(side)):
            continue
        # a junction of a larger board stays symmetric out to a third of a square; the corners of
        # the outer squares against a thin white border and the background beyond do not
        r = max(3.0, 0.3 * float(np.nanmedian(spacing[sel])))
        found[sel] = xjunction_test(light, pr[sel], r)[0]
        if found[sl].sum() >= max(2, 0.5 * len(side)):
            return True
    return False


# --- ChArUco ------------------------------------------------------------------------------------

def _detect_charuco(grey: np.ndarray, board: Board):
    ids_all, p_board = board_points(board)
    found = None
    for legacy in ((False, True) if board.rows % 2 == 0 else (False,)):
        params = cv2.aruco.CharucoParameters()
        params.tryRefineMarkers = True
        det = cv2.aruco.CharucoDetector(charuco_board(board, legacy), params)
        cc, ci, mc, mi = det.detectBoard(grey)
        if ci is not None and len(ci) >= _MIN_POINTS:
            found = (cc.reshape(-1, 2).astype(np.float64), ci.ravel().astype(np.int64), mc)
            break
    if found is None:
        return None
    xy, ids, mc = found
    # refinement radius: below the distance from a corner to the nearest marker corner
    sides = np.array([np.linalg.norm(np.diff(np.vstack([m.reshape(4, 2), m.reshape(4, 2)[:1]]), axis=0), axis=1).mean()
                      for m in mc])
    centres = np.array([m.reshape(4, 2).mean(axis=0) for m in mc])
    side_px = sides[cKDTree(centres).query(xy)[1]]
    square_px = side_px * board.square_m / board.marker_m
    gap_px = (board.square_m - board.marker_m) / board.square_m * square_px / np.sqrt(2.0)
    radius = np.clip(np.minimum(0.2 * square_px, 0.8 * gap_px), 2.0, 8.0)
    xy, ok = refine_saddles(grey, xy, radius)
    ij = p_board[ids, :2] / board.square_m
    keep = ok & ~_inconsistent(ij, xy)
    if keep.sum() < _MIN_POINTS:
        return None
    return ids[keep], xy[keep], "charuco"


# --- AprilGrid ----------------------------------------------------------------------------------

def _detect_aprilgrid(grey: np.ndarray, board: Board):
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    corners, tag_ids, _ = cv2.aruco.ArucoDetector(aruco_dictionary(board), params).detectMarkers(grey)
    if tag_ids is None:
        return None
    tag_ids = tag_ids.ravel().astype(np.int64)
    c = np.array([q.reshape(4, 2) for q in corners], dtype=np.float64)
    valid = tag_ids < board.columns * board.rows
    _, first = np.unique(tag_ids, return_index=True)                     # a tag id seen twice: keep the first
    valid &= np.isin(np.arange(len(tag_ids)), first)
    tag_ids, c = tag_ids[valid], c[valid]
    if not len(tag_ids):
        return None
    side = np.linalg.norm(c - np.roll(c, -1, axis=1), axis=2).mean(axis=1)             # (T,) px
    bits = 8 if board.family in (None, "tag36h11", "tag36h10") else (7 if board.family == "tag25h9" else 6)
    inner = side / bits                                           # the black border's width, px
    outer = np.minimum(side * board.spacing_m / board.tag_m / 2.0, side)
    xy, ok = refine_square_corners(grey, c, inner_px=0.8 * inner, outer_px=0.8 * outer)
    ids = (4 * tag_ids[:, None] + np.arange(4)[None]).ravel()
    keep = ok.ravel()
    if keep.sum() < _MIN_POINTS:
        return None
    return ids[keep], xy.reshape(-1, 2)[keep], "aprilgrid"
