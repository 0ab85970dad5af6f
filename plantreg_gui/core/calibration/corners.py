"""Chessboard corners in one grey image: found (OpenCV's SB and classic detectors), checked
(:func:`_saddles_ok`), polished (:func:`refine_corners`) and put in a unique order across
cameras (:func:`canonical_order`).

``cv2.findChessboardCornersSB`` is robust to low contrast and finds positive and negative boards
alike; the classic ``findChessboardCorners`` is the fallback; then ``cornerSubPix`` with a window
sized to the local square size (:func:`refine_corners`: halves the error on rendered boards).

**Corner order rule.** A detector may return the grid starting at any of its four corners.
:func:`canonical_order` fixes it in two steps:

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
the positive one), so it comes from :class:`~.detection.DetectOptions` ``invert`` or, when that
is None, from the camera's modality (thermal = inverted).
"""

from __future__ import annotations

import cv2
import numpy as np

from .board import Board


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


def canonical_permutation(corners: np.ndarray, gray: np.ndarray, board: Board, inverted: bool) -> np.ndarray:
    """Indices (N,) that put chessboard corners (N, 2) in the board order (rule in the module
    docstring): ``corners[perm]`` is ordered."""
    idx = np.arange(board.rows * board.columns).reshape(board.rows, board.columns)
    g = np.asarray(corners, np.float32).reshape(board.rows, board.columns, 2)
    ex = g[0, -1] - g[0, 0]
    ey = g[-1, 0] - g[0, 0]
    if ex[0] * ey[1] - ex[1] * ey[0] < 0:  # mirrored: reverse the rows
        idx = idx[::-1]
    perm = idx.ravel()
    c = np.asarray(corners, np.float32).reshape(-1, 2)[perm]
    if board.is_symmetric:
        # no colour cue: first corner nearest the image's top-left
        if (c[-1, 0] + c[-1, 1]) < (c[0, 0] + c[0, 1]):
            perm = perm[::-1]
        return np.ascontiguousarray(perm)
    mb, mw = _square_means(gray, c, board)
    black_is_dark = mb < mw
    if black_is_dark == bool(inverted):  # the "black" squares have the wrong brightness
        perm = perm[::-1]
    return np.ascontiguousarray(perm)


def canonical_order(corners: np.ndarray, gray: np.ndarray, board: Board, inverted: bool) -> np.ndarray:
    """Reorder chessboard corners (N, 2) to the board order (rule in the module docstring)."""
    c = np.asarray(corners, np.float32).reshape(-1, 2)
    return np.ascontiguousarray(c[canonical_permutation(c, gray, board, inverted)])


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


def min_spacing(corners: np.ndarray, board: Board) -> float:
    """The smallest distance (px) between neighbouring corners (N, 2) of a chessboard grid."""
    g = np.asarray(corners).reshape(board.rows, board.columns, 2)
    return min(float(np.linalg.norm(np.diff(g, axis=0), axis=2).min()),
               float(np.linalg.norm(np.diff(g, axis=1), axis=2).min()))


def refine_corners(gray: np.ndarray, corners: np.ndarray, board: Board, guard: bool = True) -> np.ndarray:
    """Polish chessboard corners (N, 2) with ``cv2.cornerSubPix``, its half-window 40 % of the
    smallest corner spacing in the image (so it never reaches a neighbouring corner). On rendered
    boards with known truth this halves the SB detector's error and removes its ~0.02 px bias.
    With ``guard``, a corner that would move by more than a third of the window keeps its
    position (without: the classic detector's rough corners, which must move)."""
    spacing = min_spacing(corners, board)
    w = int(np.clip(0.4 * spacing, 2, 15))
    c = cv2.cornerSubPix(gray.astype(np.float32), corners.reshape(-1, 1, 2).astype(np.float32).copy(), (w, w), (-1, -1),
                         (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-4)).reshape(-1, 2)
    if guard:
        moved = np.linalg.norm(c - corners, axis=1) > max(1.0, w / 3.0)
        c[moved] = corners[moved]
    return c


def _saddles_ok(img: np.ndarray, corners: np.ndarray, board: Board, min_share: float = 0.9) -> bool:
    """Whether the grid's corners are checker saddle points: around each, the diagonal quadrants
    alike and the other two of the other colour, for at least ``min_share`` of the corners. A grid
    one square too large (a 10 x 7 "found" on a 9 x 6 board, its outer corners on the board's
    edge, where a square meets the margin) fails this."""
    g = np.asarray(corners, np.float64).reshape(board.rows, board.columns, 2)
    ex = np.gradient(g, axis=1)  # along a row, one corner spacing
    ey = np.gradient(g, axis=0)
    sm = cv2.GaussianBlur(img.astype(np.float32), (0, 0), 1.0)
    h, w = sm.shape

    def at(p):
        u = np.clip(np.round(p[..., 0]).astype(int), 0, w - 1)
        v = np.clip(np.round(p[..., 1]).astype(int), 0, h - 1)
        return sm[v, u]
    a, b = at(g + 0.3 * (ex + ey)), at(g - 0.3 * (ex + ey))
    c, d = at(g + 0.3 * (ex - ey)), at(g - 0.3 * (ex - ey))
    dc = (c + d - a - b) / 2.0
    sep = np.where(dc > 0, np.minimum(c, d) - np.maximum(a, b), np.minimum(a, b) - np.maximum(c, d))
    saddle = sep > 0.3 * np.abs(dc)  # both diagonal pairs clearly apart (a margin is neither)
    return float(saddle.mean()) >= min_share


#: a grid whose corner leaves the line of its neighbours by more than this share of their spacing
#: may have a corner that is not where the detector put it (a glinting foil square pulled SB's
#: corner onto the board's edge, 60 px away: 0.45-0.95 on the ZED 2i views); correct grids on the
#: real sets reach 0.37 (a steep hand-held view; the Lepton's k1 = -0.4: 0.30). Only a choice
#: between two detectors' grids, never a refusal.
MAX_IRREGULARITY = 0.4


def grid_irregularity(corners: np.ndarray, board: Board) -> float:
    """The largest second difference of the chessboard grid ``corners`` (N, 2) along its rows and
    columns, relative to the local corner spacing: ~0.1-0.3 for a real lens, ~1 for a corner
    that sits a square away from its place."""
    g = np.asarray(corners, np.float64).reshape(board.rows, board.columns, 2)
    worst = 0.0
    for a in (0, 1):
        if g.shape[a] < 3:
            continue
        gg = np.moveaxis(g, a, 0)
        d2 = np.linalg.norm(gg[:-2] - 2 * gg[1:-1] + gg[2:], axis=-1)
        span = np.linalg.norm(gg[2:] - gg[:-2], axis=-1) / 2.0
        worst = max(worst, float(np.max(d2 / np.maximum(span, 1e-9))))
    return worst


def _settle_classic(img: np.ndarray, corners: np.ndarray, board: Board) -> np.ndarray | None:
    """The classic detector's corners (the quads' corners, ~1 px off) moved onto the saddle
    points; None when one would move further than a fifth of the corner spacing (at least 2 px):
    then it did not sit on a corner it could find."""
    c = refine_corners(img, corners, board, guard=False)
    if float(np.linalg.norm(c - corners, axis=1).max()) > max(2.0, 0.2 * min_spacing(corners, board)):
        return None
    return c


def _find_any(img: np.ndarray, pattern: tuple[int, int], thorough: bool,
              sb_first: bool = False) -> tuple[np.ndarray | None, str]:
    """Cheap first: the classic detector on the image and on its negative (it only finds dark
    squares on light; milliseconds on a clear board), then the SB detector (polarity-free,
    robust to blur and low contrast; its corners are refined later anyway), plain and normalised;
    when ``thorough``: the SB detector's exhaustive search. ``sb_first`` (upscaled tiny images,
    where SB is cheap and its start points refine better): SB before classic. Returns (corners
    (N, 2) or None, "classic" | "sb")."""
    def classic():
        for im in (img, 255 - img):
            ok, c = cv2.findChessboardCorners(im, pattern, flags=cv2.CALIB_CB_ADAPTIVE_THRESH
                                              | cv2.CALIB_CB_NORMALIZE_IMAGE)
            if ok:
                return c.reshape(-1, 2), "classic"
        return None, ""

    def sb():
        for fl in [0, cv2.CALIB_CB_NORMALIZE_IMAGE] if not thorough else [_SB_ACC | cv2.CALIB_CB_EXHAUSTIVE]:
            ok, c = cv2.findChessboardCornersSB(img, pattern, flags=fl)
            if ok:
                return c.reshape(-1, 2), "sb"
        return None, ""

    for step in ((sb,) if thorough else (sb, classic) if sb_first else (classic, sb)):
        c, how = step()
        if c is not None:
            return c, how
    return None, ""

