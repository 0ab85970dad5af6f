"""Board corner detection with a unique corner order across cameras.

Images of any modality are first turned into 8-bit grey (:func:`to_gray`): colour -> luma,
multi-band cubes -> band mean, 16-bit and float (thermal) -> percentiles 0.5 / 99.5 stretched to
0..255; optional CLAHE for low-contrast images.

Chessboards: ``cv2.findChessboardCornersSB`` (robust to low contrast, finds positive and negative
boards alike), the classic ``findChessboardCorners`` as a fallback; then ``cornerSubPix`` with a
window sized to the local square size (:func:`refine_corners`: halves the error on rendered boards).
ChArUco: ``cv2.aruco.CharucoDetector``; corners keep their board ids.

**Corner order rule** (chessboards). A detector may return the grid starting at any of its four
corners. :func:`canonical_order` fixes it in two steps:

1. *Handedness*: the printed side faces the camera, so the board's x axis (corner 0 -> 1) and y
   axis (corner 0 -> ``columns``) must turn clockwise in the image (``cross > 0`` in pixel
   coordinates, v down). If not, the rows are reversed (a mirrored order).
2. *Colour*: the first interior square (between corners 0, 1, ``columns``, ``columns+1``) is
   black on the printed board (see :mod:`.board`). We compare the mean grey of all interior squares
   that must be black with those that must be white; with the board's *polarity* (``inverted``:
   a heated board in a thermal camera glows where the print is black) the expected relation is
   known, and if it does not hold the order is rotated by 180 degrees (reversed).

Step 2 needs an asymmetric board (``columns + rows`` odd; e.g. 15 x 8): a symmetric one looks the
same rotated, so its order falls back to "first corner nearest the image's top-left" and cameras
may disagree -- :class:`~.board.Board` reports ``is_symmetric`` so the UI can warn. The polarity
cannot be read from a single image (a negative board rotated by 180 degrees looks exactly like
the positive one), so it comes from :class:`DetectOptions` ``invert`` or, when that is None,
from the camera's modality (thermal = inverted).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import cv2
import numpy as np

from ..camera import modality as _modality
from ..errors import InputError
from ..io.imageio import read_image
from ..progress import Reporter, ensure_reporter
from .board import Board

FOUND, FAILED, MISSING = "found", "failed", "missing"
DETECTORS = ("auto", "classic")


@dataclass
class DetectOptions:
    """Per-image detection options.

    ``invert``: board polarity. True = the board appears as a negative (heated board in a thermal
    camera), False = normal print, None = decided by the camera's modality (thermal -> True).
    Detection itself always tries the image and its negative; ``invert`` decides the corner order.
    ``enhance``: apply CLAHE (local contrast) before detection, for faint thermal boards.
    ``detector`` (chessboards): ``"auto"`` = ``findChessboardCornersSB`` with the classic detector
    as a fallback; ``"classic"`` = OpenCV's classic pipeline only (``findChessboardCorners`` +
    ``cornerSubPix`` with an 11 x 11 half-window, as OpenCV's ``stereo_calib`` sample does) --
    kept for comparison with published figures; its large window is biased where foreshortened
    squares are smaller than ~24 px.
    """

    invert: bool | None = None
    enhance: bool = False
    detector: str = "auto"

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"invert": self.invert, "enhance": bool(self.enhance)}
        if self.detector != "auto":
            d["detector"] = self.detector
        return d

    @classmethod
    def from_dict(cls, d: Any) -> "DetectOptions":
        if not isinstance(d, dict):
            raise ValueError("detection options must be an object")
        inv = d.get("invert")
        det = str(d.get("detector", "auto"))
        if det not in DETECTORS:
            raise ValueError(f"detector must be one of {', '.join(DETECTORS)}")
        return cls(None if inv is None else bool(inv), bool(d.get("enhance", False)), det)


@dataclass
class Detection:
    """Result of one image. ``corners`` (N, 2) float32 in board order (chessboard: all
    ``columns * rows`` corners; ChArUco: the corners found, ids in ``ids`` (N,) int32), None unless
    ``status == "found"``. ``image_size`` (w, h). ``inverted`` = the polarity used for ordering.
    ``path`` the image file (None for in-memory images)."""

    pose: str
    camera: str
    status: str
    reason: str
    corners: np.ndarray | None
    ids: np.ndarray | None
    image_size: tuple[int, int]
    inverted: bool
    path: Path | None = None
    options: DetectOptions = field(default_factory=DetectOptions)

    @property
    def found(self) -> bool:
        return self.status == FOUND

    @property
    def key(self) -> tuple[str, str]:
        return (self.pose, self.camera)

    def object_points(self, board: Board) -> np.ndarray:
        """Board-frame points (N, 3) matching ``corners``."""
        obj = board.object_points()
        return obj if self.ids is None else obj[self.ids]


# ---------------------------------------------------------------------- image preparation
def to_gray(image: np.ndarray, enhance: bool = False) -> np.ndarray:
    """Any image (H, W), (H, W, 3|4) or a cube (H, W, B), of any dtype -> uint8 grey (H, W)."""
    img = np.asarray(image)
    if img.ndim == 3:
        if img.shape[2] in (3, 4) and img.dtype == np.uint8:
            img = cv2.cvtColor(np.ascontiguousarray(img[:, :, :3]), cv2.COLOR_RGB2GRAY)
        elif img.shape[2] in (3, 4):
            img = img[:, :, :3].astype(np.float64) @ np.array([0.299, 0.587, 0.114])
        else:  # hyperspectral: the band mean has the best SNR for a grey board
            img = np.nanmean(img.astype(np.float32), axis=2)
    if img.dtype != np.uint8:
        f = img.astype(np.float32)
        finite = np.isfinite(f)
        if not finite.any():
            return np.zeros(f.shape, np.uint8)
        lo, hi = np.percentile(f[finite], [0.5, 99.5])
        f = np.where(finite, f, lo)
        img = np.clip((f - lo) * (255.0 / max(float(hi - lo), 1e-12)), 0, 255).astype(np.uint8)
    if enhance:
        img = cv2.createCLAHE(clipLimit=3.0, tileGridSize=(8, 8)).apply(img)
    return np.ascontiguousarray(img)


# ---------------------------------------------------------------------- chessboard
def _square_means(gray: np.ndarray, corners: np.ndarray, board: Board) -> tuple[float, float]:
    """Mean grey of interior squares that must be black vs white (in the given order)."""
    g = corners.reshape(board.rows, board.columns, 2)
    centres = (g[:-1, :-1] + g[1:, :-1] + g[:-1, 1:] + g[1:, 1:]) / 4.0  # (rows-1, cols-1, 2)
    jj, ii = np.mgrid[0 : board.rows - 1, 0 : board.columns - 1]
    black = board.square_is_black(ii + 1, jj + 1)  # square between corners i..i+1 is a = i + 1
    h, w = gray.shape
    # sample a small cross around each centre (robust to blur and noise)
    d = 0.15 * (g[1:, 1:] - g[:-1, :-1])
    vals = []
    for f in (0.0, 1.0, -1.0):
        p = centres + f * d
        u = np.clip(np.round(p[..., 0]).astype(int), 0, w - 1)
        v = np.clip(np.round(p[..., 1]).astype(int), 0, h - 1)
        vals.append(gray[v, u].astype(np.float64))
    m = np.mean(vals, axis=0)
    return float(m[black].mean()), float(m[~black].mean())


def canonical_order(corners: np.ndarray, gray: np.ndarray, board: Board, inverted: bool) -> np.ndarray:
    """Reorder chessboard corners (N, 2) to the board order (rule in the module docstring)."""
    g = np.asarray(corners, np.float32).reshape(board.rows, board.columns, 2)
    ex = g[0, -1] - g[0, 0]
    ey = g[-1, 0] - g[0, 0]
    if ex[0] * ey[1] - ex[1] * ey[0] < 0:  # mirrored: reverse the rows
        g = g[::-1]
    c = g.reshape(-1, 2)
    if board.is_symmetric:
        # no colour cue: first corner nearest the image's top-left
        if (c[-1, 0] + c[-1, 1]) < (c[0, 0] + c[0, 1]):
            c = c[::-1]
        return np.ascontiguousarray(c)
    mb, mw = _square_means(gray, c, board)
    black_is_dark = mb < mw
    if black_is_dark == bool(inverted):  # the "black" squares have the wrong brightness
        c = c[::-1]
    return np.ascontiguousarray(c)


_SB_ACC = cv2.CALIB_CB_ACCURACY


def _find_classic(gray: np.ndarray, pattern: tuple[int, int], win: int = 11) -> np.ndarray | None:
    for img in (gray, 255 - gray):
        ok, c = cv2.findChessboardCorners(img, pattern, flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
        if ok:
            c = cv2.cornerSubPix(gray, c, (win, win), (-1, -1),
                                 (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01))
            return c.reshape(-1, 2)
    return None


def _find_chessboard(gray: np.ndarray, pattern: tuple[int, int], thorough: bool = True,
                     detector: str = "auto") -> np.ndarray | None:
    if detector == "classic":
        return _find_classic(gray, pattern)
    # CALIB_CB_NORMALIZE_IMAGE (histogram equalisation) hurts when a small board sits on a large
    # dark background (infrared), so plain first, normalised second, exhaustive last. The SB
    # detector finds positive and negative boards alike, so no inverted attempt is needed here.
    attempts = [(gray, _SB_ACC), (gray, _SB_ACC | cv2.CALIB_CB_NORMALIZE_IMAGE)]
    if thorough:
        attempts += [(gray, _SB_ACC | cv2.CALIB_CB_EXHAUSTIVE)]
    for img, flags in attempts:
        ok, c = cv2.findChessboardCornersSB(img, pattern, flags=flags)
        if ok:
            return c.reshape(-1, 2)
    if not thorough:
        return None
    # classic detector + sub-pixel refinement (handles some blurry images SB misses)
    return _find_classic(gray, pattern, win=5)


def refine_corners(gray: np.ndarray, corners: np.ndarray, board: Board) -> np.ndarray:
    """Polish chessboard corners (N, 2) with ``cv2.cornerSubPix``, its half-window 40 % of the
    smallest corner spacing in the image (so it never reaches a neighbouring corner). On rendered
    boards with known truth this halves the SB detector's error and removes its ~0.02 px bias.
    A corner that would move by more than a third of the window keeps its position."""
    g = corners.reshape(board.rows, board.columns, 2)
    spacing = min(float(np.linalg.norm(np.diff(g, axis=0), axis=2).min()),
                  float(np.linalg.norm(np.diff(g, axis=1), axis=2).min()))
    w = int(np.clip(0.4 * spacing, 2, 15))
    c = cv2.cornerSubPix(gray.astype(np.float32), corners.reshape(-1, 1, 2).astype(np.float32).copy(), (w, w), (-1, -1),
                         (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-4)).reshape(-1, 2)
    moved = np.linalg.norm(c - corners, axis=1) > max(1.0, w / 3.0)
    c[moved] = corners[moved]
    return c


def _detect_charuco(gray: np.ndarray, board: Board):
    det = cv2.aruco.CharucoDetector(board.charuco())
    best = (None, None)
    for img in (gray, 255 - gray):
        ch_corners, ch_ids, _, _ = det.detectBoard(img)
        if ch_ids is not None and len(ch_ids) >= 4 and (best[1] is None or len(ch_ids) > len(best[1])):
            best = (ch_corners.reshape(-1, 2).astype(np.float32), ch_ids.ravel().astype(np.int32))
    return best


def detect_image(image: np.ndarray, board: Board, options: DetectOptions | None = None,
                 modality: str | None = None) -> Detection:
    """Detect the board in one image. Returns a :class:`Detection` with empty ``pose``/``camera``
    (status ``found`` or ``failed`` with a reason). ``modality`` only matters when
    ``options.invert`` is None (thermal -> inverted polarity)."""
    options = options or DetectOptions()
    inverted = options.invert if options.invert is not None else _modality.inverted_board(modality)
    img = np.asarray(image)
    size = (int(img.shape[1]), int(img.shape[0]))
    gray = to_gray(img, options.enhance)

    def fail(reason: str) -> Detection:
        return Detection("", "", FAILED, reason, None, None, size, inverted, None, options)

    if gray.max() == gray.min():
        return fail("the image is blank (one value everywhere)")
    if board.type == "charuco":
        corners, ids = _detect_charuco(gray, board)
        if corners is None:
            return fail("no ChArUco corners found (check dictionary and marker size, or the image is too dark/blurred)")
        if len(ids) < 6:
            return fail(f"only {len(ids)} ChArUco corners found (need 6)")
        if cv2.aruco.CharucoBoard.checkCharucoCornersCollinear(board.charuco(), ids.reshape(-1, 1)):
            return fail("the ChArUco corners found are collinear (too little of the board is visible)")
        order = np.argsort(ids)
        return Detection("", "", FOUND, "", corners[order], ids[order], size, inverted, None, options)
    corners = _find_chessboard(gray, board.pattern_size, detector=options.detector)
    if corners is None:
        return fail(f"no {board.columns}x{board.rows} inner-corner chessboard found"
                    + ("" if options.enhance else " (try contrast enhancement)"))
    if options.detector != "classic":
        corners = refine_corners(gray, corners, board)
    corners = canonical_order(corners, gray, board, inverted)
    return Detection("", "", FOUND, "", corners.astype(np.float32), None, size, inverted, None, options)


def suggest_board_size(images: list[np.ndarray], board: Board) -> tuple[int, int] | None:
    """When nothing is found: try nearby inner-corner counts (the usual mistake is counting
    squares, i.e. one too many each way) on a few images; return the first (columns, rows) that
    is found, or None."""
    c, r = board.columns, board.rows
    candidates = [(c - 1, r - 1), (r, c), (c - 1, r), (c, r - 1), (c + 1, r + 1), (r - 1, c - 1),
                  (c + 1, r), (c, r + 1), (c - 2, r - 2)]
    seen = set()
    for cand in candidates:
        if cand in seen or min(cand) < 2 or cand == (c, r):
            continue
        seen.add(cand)
        for img in images[:3]:
            if _find_chessboard(to_gray(img), cand, thorough=False) is not None:
                return cand
    return None


# ---------------------------------------------------------------------- sessions
def detect_view(session, pose, camera: str, options: DetectOptions | None = None,
                image: np.ndarray | None = None) -> Detection:
    """Detect one (pose, camera) of a session (a missing image gives status ``missing``).
    ``image``: the view's image if already read. Unreadable files raise :class:`InputError`."""
    path = pose.images.get(camera)
    if path is None:
        return Detection(pose.name, camera, MISSING, f"no image of camera '{camera}' in this pose",
                         None, None, (0, 0), False, None, options or DetectOptions())
    opts = options or DetectOptions()
    if opts.invert is None:
        opts = DetectOptions(session.default_inverted(camera), opts.enhance, opts.detector)
    img = read_image(path) if image is None else image
    det = detect_image(img, session.board, opts, session.cameras.get(camera))
    det.pose, det.camera, det.path = pose.name, camera, Path(path)
    det.options = options or DetectOptions()
    return det


def detect_session(session, options: dict[tuple[str, str], DetectOptions] | None = None,
                   progress: Reporter | None = None,
                   views: list[tuple[str, str]] | None = None) -> Iterator[Detection]:
    """Detect every (pose, camera) of the session; a generator yielding each :class:`Detection`
    as it is done (poses in order, cameras in session order), so a GUI can fill a table as
    results arrive. ``options`` per image override the session's stored review options.
    ``views`` restricts the work to some (pose, camera) pairs. Each step is a cancellation point
    (``progress`` raises :class:`Cancelled`); stopping the iteration also stops the work.
    Unreadable images raise :class:`InputError` naming the file.
    """
    progress = ensure_reporter(progress)
    opts = session.detect_options()
    opts.update(options or {})
    todo = [(p, c) for p in session.poses for c in session.cameras
            if views is None or (p.name, c) in set(views)]
    n = max(1, len(todo))
    for k, (pose, cam) in enumerate(todo):
        progress(k / n, f"detecting {pose.name}/{cam}")
        yield detect_view(session, pose, cam, opts.get((pose.name, cam)))
    progress(1.0, "detection done")


def check_image_sizes(session, detections: dict[tuple[str, str], Detection]) -> dict[str, tuple[int, int]]:
    """The image size (w, h) of each camera; raises :class:`InputError` naming the first image
    whose size differs from the camera's other images."""
    sizes: dict[str, tuple[int, int, Path | None]] = {}
    for (pose, cam), d in sorted(detections.items()):
        if d.status == MISSING:
            continue
        if cam not in sizes:
            sizes[cam] = (*d.image_size, d.path)
        elif tuple(sizes[cam][:2]) != tuple(d.image_size):
            w, h, first = sizes[cam]
            raise InputError(
                f"image is {d.image_size[0]}x{d.image_size[1]} but the other images of camera '{cam}' "
                f"are {w}x{h} (e.g. {first}); one camera must always deliver the same size", d.path)
    return {k: (v[0], v[1]) for k, v in sizes.items()}
