"""Board detection in one image (:func:`detect_image`): the image becomes a scalar
(:mod:`.imageprep`), then the variants of :data:`~.detection.VARIANTS` (plain, background
removed, CLAHE, upscaled, exhaustive, full resolution) are tried in order until the whole board
is found (:mod:`.corners` finds, checks, refines and orders the corners); ChArUco boards keep
the variant with most corners. Also :func:`suggest_board_size` for a board stated wrongly.
"""

from __future__ import annotations

import cv2
import numpy as np

from ..camera import modality as _modality
from .board import Board
from .corners import (MAX_IRREGULARITY, _find_any, _find_chessboard, _find_classic, _saddles_ok, _settle_classic,
                      canonical_order, canonical_permutation, grid_irregularity, min_spacing, refine_corners)
from .detection import FAILED, FOUND, Detection, DetectOptions
from .imageprep import WORK_SIDE, _resize, _stretch, _to_image_px, flatten, to_gray, to_scalar, work_scale


#: A board found in a downscaled image whose corners are closer than this (px, there) is detected
#: again at a larger scale: below it the SB detector may take the board's edge for corners.
MIN_SPACING_PX = 12.0


def _square_px(size: tuple[int, int], board: Board) -> float:
    """A board square's size in px when the board fills about half the image's shorter side."""
    return 0.5 * min(size) / (max(board.columns, board.rows) + 1)


def _variant_images(f: np.ndarray, board: Board, enhance: bool):
    """Yield (variant, uint8 image, thorough, zoom) in the order tried; ``f`` the working-scale
    scalar, ``zoom`` the image's size relative to ``f`` (2: "fine-2x", small squares doubled)."""
    plain = _stretch(f)
    sq = _square_px((f.shape[1], f.shape[0]), board)
    order = ["clahe", "plain", "flat", "flat-fine"] if enhance else ["plain", "flat", "flat-fine", "clahe"]
    made: dict[str, np.ndarray] = {}
    for v in order:
        if v == "plain":
            made[v] = plain
        elif v == "flat":
            made[v] = flatten(f, max(2.0, sq / 2.0))
        elif v == "flat-fine":
            made[v] = flatten(f, max(1.5, sq / 4.0))
        else:
            made[v] = cv2.createCLAHE(clipLimit=3.0, tileGridSize=(8, 8)).apply(plain)
        yield v, made[v], False, 1.0
    if max(f.shape) <= WORK_SIDE:  # a small, far or steep board: its squares doubled
        yield "fine-2x", flatten(_resize(f, 2.0), max(1.5, sq / 3.0)), False, 2.0
    yield "thorough", made["plain"], True, 1.0
    yield "thorough", made["flat"], True, 1.0


def _highpass(f: np.ndarray, sigma: float) -> np.ndarray:
    """``f`` minus its Gaussian blur of ``sigma`` px; a wide blur is taken on a copy shrunk by up
    to sigma / 2 (what it keeps varies slowly) and enlarged again."""
    f = np.asarray(f, np.float32)
    k = int(max(1, sigma // 2))
    if k < 2:
        return f - cv2.GaussianBlur(f, (0, 0), sigma)
    h, w = f.shape
    small = cv2.resize(f, (max(1, w // k), max(1, h // k)), interpolation=cv2.INTER_AREA)
    low = cv2.resize(cv2.GaussianBlur(small, (0, 0), sigma / k), (w, h), interpolation=cv2.INTER_LINEAR)
    return f - low


def _flat_like(f: np.ndarray, variant: str, board: Board) -> np.ndarray:
    """The full-resolution image of a flattened ``variant`` (its sigma in full-size pixels)."""
    sq = _square_px((f.shape[1], f.shape[0]), board)
    return flatten(f, max(2.0, sq / 2.0) if variant != "flat-fine" else max(1.5, sq / 4.0))


def _detect_chessboard_auto(f: np.ndarray, board: Board, enhance: bool, inverted: bool, scale: float | None = None):
    """The automatic variants on a scalar image ``f`` (H, W) at the working scale (``scale``, or
    :func:`~.imageprep.work_scale`). Returns (corners (N, 2) in board order in image px, variant,
    scale) or (None, tried variants, scale)."""
    size = (f.shape[1], f.shape[0])
    s = work_scale(size) if scale is None else scale
    fw = _resize(f, s)
    plain_w = _stretch(fw)
    # the saddle check runs on a linear image without the lamp's gradient (the flattened ones
    # make a board's dark surround look like squares); made when a board is first found
    hp: list[np.ndarray] = []

    def hp_w() -> np.ndarray:
        if not hp:
            hp.append(_highpass(fw, max(2.0, _square_px((fw.shape[1], fw.shape[0]), board))))
        return hp[0]
    tried = []
    s0 = s
    for variant, img, thorough, zoom in _variant_images(fw, board, enhance):
        if variant not in tried:
            tried.append(variant)
        s = s0 * zoom
        # SB first everywhere: classic corners, even settled and refined, left the OpenCV stereo
        # sample's relative pose 0.17 deg from Bouguet's (SB's: 0.007 deg); on a faint flattened
        # board classic quads are several px off, beyond what cornerSubPix can pull back
        c, how = _find_any(img, board.pattern_size, thorough, sb_first=True)
        if c is None or not _saddles_ok(hp_w(), c, board):
            continue
        if how == "sb" and grid_irregularity(c, board) > MAX_IRREGULARITY:
            # a corner off its grid line: the classic detector's grid when it is the regular one
            c2, how2 = _find_any(img, board.pattern_size, False)
            if how2 == "classic" and _saddles_ok(hp_w(), c2, board) \
                    and grid_irregularity(c2, board) < grid_irregularity(c, board):
                # settled on the saddle points; on a glinting foil square a free refinement
                # wanders, then each corner moves only as far as the guard lets it
                c2s = _settle_classic(img, c2, board)
                c, how = (c2s if c2s is not None else refine_corners(img, c2, board)), "classic, regular grid"
        perm = canonical_permutation(c, img if variant != "clahe" else plain_w, board, inverted)
        # refined on the image that found them: on rendered lamp-heated boards with known truth the
        # flattened image gives smaller corner errors than the raw scalar (whose lamp gradient
        # biases cornerSubPix) or its linear high-pass
        if how == "classic":  # its corners are the quads' corners: bring them onto the saddle points first
            c = _settle_classic(img, c, board)
            if c is None:  # a corner ran off (faint, or beside a hot edge): the SB detector decides
                c, how = _find_any(img, board.pattern_size, False, sb_first=True)
                if how != "sb" or not _saddles_ok(img, c, board):
                    continue
                perm = canonical_permutation(c, img if variant != "clahe" else plain_w, board, inverted)
        if s < 1.0 and scale is None and (sp := min_spacing(c, board)) < MIN_SPACING_PX:
            # a small or steep board in a downscaled image: the SB detector can take its edge for
            # a row of corners; detect again around it, at a scale where its squares are large enough
            again = _detect_around(f, _to_image_px(c, s), board, enhance, inverted,
                                   min(1.0, 1.5 * MIN_SPACING_PX * s / sp))
            if again[0] is not None:
                return again
        if s > 1.0:  # upscaled: refine on the upscaled variant image, then back to image px
            c = _to_image_px(refine_corners(img, c, board), s)
        elif s < 1.0:  # downscaled: refine on the full-resolution image (cornerSubPix needs no stretch)
            c = refine_corners(f if variant in ("plain", "clahe") else _flat_like(f, variant, board), _to_image_px(c, s),
                               board)
        else:
            c = refine_corners(img, c, board)
        return c[perm], variant, s
    s = s0
    if s < 1.0:  # a board too small for the downscaled image
        tried.append("full-res")
        img = _stretch(f)
        c, how = _find_any(img, board.pattern_size, False)
        if c is None:
            img = flatten(f, max(2.0, _square_px(size, board) / 2.0))
            c, how = _find_any(img, board.pattern_size, False)
        if c is not None and _saddles_ok(img, c, board):
            perm = canonical_permutation(c, img, board, inverted)
            if how == "classic":
                c2 = _settle_classic(img, c, board)
                c = c if c2 is None else c2
            return refine_corners(img, c, board)[perm], "full-res", 1.0
    return None, tried, s


def _detect_around(f: np.ndarray, corners: np.ndarray, board: Board, enhance: bool, inverted: bool, scale: float):
    """:func:`_detect_chessboard_auto` at ``scale`` on the part of ``f`` around ``corners`` (N, 2)
    (image px; their box grown by half its size each way: the board's outer squares, even when
    the corners found first were a row off); the result in image px."""
    lo, hi = corners.min(0), corners.max(0)
    m = 0.5 * float(np.max(hi - lo))
    x0, y0 = (max(0, int(v - m)) for v in lo)
    x1, y1 = min(f.shape[1], int(hi[0] + m) + 1), min(f.shape[0], int(hi[1] + m) + 1)
    c, variant, s = _detect_chessboard_auto(f[y0:y1, x0:x1], board, enhance, inverted, scale)
    if c is None:
        return c, variant, s
    return (c + np.array([x0, y0], np.float32)).astype(np.float32), variant, s


def _detect_charuco(gray: np.ndarray, board: Board):
    det = cv2.aruco.CharucoDetector(board.charuco())
    best = (None, None)
    for img in (gray, 255 - gray):
        ch_corners, ch_ids, _, _ = det.detectBoard(img)
        if ch_ids is not None and len(ch_ids) >= 4 and (best[1] is None or len(ch_ids) > len(best[1])):
            best = (ch_corners.reshape(-1, 2).astype(np.float32), ch_ids.ravel().astype(np.int32))
    return best


def _detect_charuco_auto(f: np.ndarray, board: Board, enhance: bool):
    """ChArUco on the plain, background-removed and CLAHE images; the one with most corners
    (stops when all are found). Returns (corners, ids, variant)."""
    plain = _stretch(f)
    n_all = (board.columns) * (board.rows)
    best = (None, None, "")
    sq = _square_px((f.shape[1], f.shape[0]), board)
    makers = [("plain", lambda: plain), ("flat", lambda: flatten(f, max(2.0, sq / 2.0))),
              ("clahe", lambda: cv2.createCLAHE(clipLimit=3.0, tileGridSize=(8, 8)).apply(plain))]
    if enhance:
        makers = makers[2:] + makers[:2]
    for variant, make in makers:
        c, ids = _detect_charuco(make(), board)
        if c is not None and (best[1] is None or len(ids) > len(best[1])):
            best = (c, ids, variant)
        if best[1] is not None and len(best[1]) >= n_all:
            break
    return best


def detect_image(image: np.ndarray, board: Board, options: DetectOptions | None = None,
                 modality: str | None = None) -> Detection:
    """Detect the board in one image. Returns a :class:`Detection` with empty ``pose``/``camera``
    (status ``found`` or ``failed`` with a reason). ``modality`` only matters when
    ``options.invert`` is None (thermal -> inverted polarity).

    The image becomes a scalar (:func:`to_scalar`: palette images by palette index), then the
    variants of :data:`VARIANTS` are tried in order until the whole board is found; which one
    found it is recorded in ``variant``/``conversion``/``scale``."""
    options = options or DetectOptions()
    inverted = options.invert if options.invert is not None else _modality.inverted_board(modality)
    img = np.asarray(image)
    size = (int(img.shape[1]), int(img.shape[0]))
    f, conversion = to_scalar(img)

    def fail(reason: str, variant: str = "") -> Detection:
        return Detection("", "", FAILED, reason, None, None, size, inverted, None, options, variant, conversion)

    finite = np.isfinite(f)
    if not finite.any() or float(np.nanmax(f)) == float(np.nanmin(f)):
        return fail("the image is blank (one value everywhere)")
    if board.type == "charuco":
        corners, ids, variant = _detect_charuco_auto(f, board, options.enhance)
        if corners is None:
            return fail("no ChArUco corners found (check dictionary and marker size, or the image is too dark/blurred)")
        if len(ids) < 6:
            return fail(f"only {len(ids)} ChArUco corners found (need 6)")
        if cv2.aruco.CharucoBoard.checkCharucoCornersCollinear(board.charuco(), ids.reshape(-1, 1)):
            return fail("the ChArUco corners found are collinear (too little of the board is visible)")
        order = np.argsort(ids)
        return Detection("", "", FOUND, "", corners[order], ids[order], size, inverted, None, options,
                         variant, conversion)
    if options.detector == "classic":
        gray = to_gray(img, options.enhance)
        corners = _find_classic(gray, board.pattern_size)
        if corners is None:
            return fail(f"no {board.columns}x{board.rows} inner-corner chessboard found by the classic detector",
                        "classic")
        corners = canonical_order(corners, gray, board, inverted)
        return Detection("", "", FOUND, "", corners.astype(np.float32), None, size, inverted, None, options,
                         "classic", conversion)
    corners, variant, scale = _detect_chessboard_auto(f, board, options.enhance, inverted)
    if corners is None:
        return fail(f"no {board.columns}x{board.rows} inner-corner chessboard found (tried: {', '.join(variant)}"
                    f"{'' if scale == 1 else f'; detected at {scale:g}x'}); check the board size and that "
                    "the whole board is in the image")
    return Detection("", "", FOUND, "", corners.astype(np.float32), None, size, inverted, None, options,
                     variant, conversion, scale)


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

