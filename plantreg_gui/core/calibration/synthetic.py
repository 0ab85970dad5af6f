"""Synthetic calibration sessions of a known rig (ground truth for tests, the demo and the wizard).

:func:`write_calibration_session` renders a chessboard in many poses into every camera of a rig:

* per pixel, the ray through the pixel centre (through the camera's distortion, OpenCV's
  ``undistortPoints``) is intersected with the board plane; the pattern is anti-aliased
  analytically with the pixel's footprint on the board (a box filter of the square wave along
  each board axis, from the ray Jacobian), so edges and corners sit exactly where the geometry
  puts them; then optical blur and sensor noise per modality;
* visible cameras: uint8 RGB; the infrared (depth) camera: uint16 with active-illumination
  fall-off; thermal: float32 degrees C of a *heated* board (printed squares warm -> the image is a
  photographic negative), blurred and low-contrast; hyperspectral: float32 (H, W, B) reflectance;
* depth maps of the board for the depth camera: z of the plane in the depth camera's frame,
  plus a per-pose ToF bias and noise, quantised to depth units (``rig.depth_scale``);
* board poses cover the plants' depth range (0.4 - 1.1 m) with tilts up to ~35 degrees.

The truth (rig, board poses ``R_rig_board``/``t_rig_board``, ToF bias per pose) is written to
``truth.json`` beside ``session.json``; :class:`~.session.Session` ignores it.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from ..camera.camera import Camera
from ..io.imageio import atomic_output_dir, atomic_write_text, write_png, write_tiff
from ..progress import Reporter, ensure_reporter
from ..camera.rig import Rig
from .board import Board
from ..camera import modality as _modality
from .session import SESSION_FILE

TRUTH_FILE = "truth.json"
DEPTH_RANGE_M = (0.4, 1.1)
MIN_SQUARE_PX = 6.0


# ---------------------------------------------------------------------- helpers
def _kind(modality: str) -> str:
    """How a camera of this modality sees the board: 'visible', 'infrared', 'thermal' or 'hyperspectral'."""
    m = _modality.canonical(modality)
    if m in ("thermal", "hyperspectral", "infrared"):
        return m
    return "infrared" if m == "depth" else "visible"


def _rot(axis: str, deg: float) -> np.ndarray:
    return cv2.Rodrigues(np.deg2rad(deg) * np.eye(3)["xyz".index(axis)])[0]


def _fov_tan(cam: Camera) -> tuple[float, float]:
    """Half field of view as tangents (x, y), from the undistorted image corners (conservative)."""
    uv = np.array([[0, cam.height / 2], [cam.width - 1, cam.height / 2],
                   [cam.width / 2, 0], [cam.width / 2, cam.height - 1]], float)
    xy = cam.undistort_normalized(uv)
    return float(min(-xy[0, 0], xy[1, 0])), float(min(-xy[2, 1], xy[3, 1]))


def choose_board(rig: Rig, depth_range: tuple[float, float] = DEPTH_RANGE_M) -> Board:
    """A 15 x 8 inner-corner chessboard (asymmetric: 15 + 8 is odd) sized so that the narrowest
    camera sees all of it at ~0.55 m while the widest still resolves the squares at the far end."""
    cols, rows = 15, 8
    # width of the narrowest camera's view at the near-ish distance, board must fit with slack
    z_fit = depth_range[0] + 0.2 * (depth_range[1] - depth_range[0])
    tx = min(_fov_tan(c)[0] for c in rig.cameras)
    ty = min(_fov_tan(c)[1] for c in rig.cameras)
    s_fit = min(2 * tx * z_fit * 0.72 / (cols + 2), 2 * ty * z_fit * 0.72 / (rows + 2))
    # at least ~7 px per square in every camera at the far end of the range
    s_min = max(7.0 * depth_range[1] / min(c.K[0, 0], c.K[1, 1]) for c in rig.cameras)
    s = max(s_fit, s_min)
    return Board("chessboard", cols, rows, round(s, 4))


class _CamRays:
    """Per-camera precomputation: normalised ray of every pixel centre and its Jacobian,
    (H, W) each, stored as float32 (4K cameras), used as float64 row band by row band."""

    _FIELDS = ("x", "y", "xu", "yu", "xv", "yv")

    def __init__(self, cam: Camera | None):
        self.cam = cam
        if cam is None:
            return
        H, W = cam.height, cam.width
        xy = cam.undistort_normalized(cam.pixel_grid()).reshape(H, W, 2)
        x, y = xy[..., 0], xy[..., 1]
        # derivatives of (x, y) wrt u (axis 1) and v (axis 0)
        self.xu = np.gradient(x, axis=1).astype(np.float32)
        self.yu = np.gradient(y, axis=1).astype(np.float32)
        self.xv = np.gradient(x, axis=0).astype(np.float32)
        self.yv = np.gradient(y, axis=0).astype(np.float32)
        # x, y keep float64: they set where the corners are
        self.x, self.y = x, y

    def band(self, a: int, b: int) -> "_CamRays":
        out = _CamRays(None)
        for f in self._FIELDS:
            setattr(out, f, getattr(self, f)[a:b].astype(np.float64))
        return out


def _board_hit(rays: _CamRays, R_cam_board: np.ndarray, t_cam_board: np.ndarray):
    """Board coordinates (qx, qy) of each pixel's ray hit, their footprints (wx, wy), hit depth z.
    All (H, W). z <= 0 or NaN where the ray misses the front of the plane."""
    n = R_cam_board[:, 2]
    nt = float(n @ t_cam_board)
    nd = n[0] * rays.x + n[1] * rays.y + n[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = nt / nd
    lam[~(lam > 0)] = np.nan
    X = lam * rays.x - t_cam_board[0]
    Y = lam * rays.y - t_cam_board[1]
    Z = lam - t_cam_board[2]
    Rt = R_cam_board.T
    qx = Rt[0, 0] * X + Rt[0, 1] * Y + Rt[0, 2] * Z
    qy = Rt[1, 0] * X + Rt[1, 1] * Y + Rt[1, 2] * Z

    def dq(xd, yd):
        # d(lam * d)/du = dlam * d + lam * dd, dlam = -lam * (n . dd) / (n . d)
        ndd = n[0] * xd + n[1] * yd
        dlam = -lam * ndd / nd
        dX = dlam * rays.x + lam * xd
        dY = dlam * rays.y + lam * yd
        dZ = dlam
        return (Rt[0, 0] * dX + Rt[0, 1] * dY + Rt[0, 2] * dZ,
                Rt[1, 0] * dX + Rt[1, 1] * dY + Rt[1, 2] * dZ)

    qxu, qyu = dq(rays.xu, rays.yu)
    qxv, qyv = dq(rays.xv, rays.yv)
    wx = np.abs(qxu) + np.abs(qxv)
    wy = np.abs(qyu) + np.abs(qyv)
    return qx, qy, wx, wy, lam


def _aa_wave(q: np.ndarray, w: np.ndarray, s: float) -> np.ndarray:
    """Box-filtered square wave: +1 where floor(q / s) is even, -1 where odd, linear ramps of
    width ``w`` centred on the edges (the exact box filter of a step)."""
    t = q / s
    k = np.floor(t)
    sign = 1.0 - 2.0 * np.mod(k, 2.0)
    d = np.minimum(t - k, k + 1.0 - t) * s
    with np.errstate(divide="ignore", invalid="ignore"):
        return sign * np.clip(2.0 * d / np.maximum(w, 1e-12), 0.0, 1.0)


def _aa_box(q: np.ndarray, w: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Box-filtered indicator of lo <= q <= hi."""
    d = np.minimum(q - lo, hi - q)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.clip(0.5 + d / np.maximum(w, 1e-12), 0.0, 1.0)


def board_texture(board: Board, px_per_square: int = 48, margin_squares: float = 0.6) -> tuple[np.ndarray, int, float]:
    """The printed board as a float32 texture (1 = paper) for boards without an analytic pattern
    (ChArUco), with its scale and margin: ``(texture, px_per_square, margin_squares)``."""
    img = board.render(px_per_square, margin_squares).astype(np.float32) / 255.0
    return img, px_per_square, margin_squares


def render_board(rays: _CamRays, board: Board, R_cam_board: np.ndarray, t_cam_board: np.ndarray,
                 margin_squares: float = 0.6, texture: tuple[np.ndarray, int, float] | None = None):
    """Reflectance of the printed board per pixel (1 = white paper, 0 = black print), the board
    coverage (0..1, incl. the white margin) and the hit depth z (H, W) (NaN off the board).

    Chessboards are anti-aliased analytically; other boards (``texture``, see
    :func:`board_texture`) are sampled from a texture low-pass filtered to the mean footprint."""
    s = board.square_size
    qx, qy, wx, wy, z = _board_hit(rays, R_cam_board, t_cam_board)
    ok = np.isfinite(qx) & np.isfinite(wx) & np.isfinite(wy)
    qx = np.where(ok, qx, -1e3)
    qy = np.where(ok, qy, -1e3)
    wx = np.where(ok, wx, s)
    wy = np.where(ok, wy, s)
    if texture is not None:
        tex, P, margin_squares = texture
        m = margin_squares * s
        cover = _aa_box(qx, wx, -s - m, board.columns * s + m) * _aa_box(qy, wy, -s - m, board.rows * s + m)
        cover[~ok] = 0.0
        foot = float(np.median(np.concatenate([wx[cover > 0], wy[cover > 0]]))) if np.any(cover > 0) else s
        sigma = max(0.3, 0.45 * P * foot / s)
        tex_f = cv2.GaussianBlur(tex, (0, 0), sigma)
        u = ((qx / s + 1.0 + margin_squares) * P - 0.5).astype(np.float32)
        v = ((qy / s + 1.0 + margin_squares) * P - 0.5).astype(np.float32)
        refl = cv2.remap(tex_f, u, v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=1.0)
        z = np.where(cover >= 1.0, z, np.nan)
        return refl.astype(np.float64), cover, z
    # square (a, b) black when a + b even  <=>  wave(qx) * wave(qy) = +1
    pattern = 0.5 - 0.5 * _aa_wave(qx, wx, s) * _aa_wave(qy, wy, s)
    in_sq = _aa_box(qx, wx, -s, board.columns * s) * _aa_box(qy, wy, -s, board.rows * s)
    m = margin_squares * s
    cover = _aa_box(qx, wx, -s - m, board.columns * s + m) * _aa_box(qy, wy, -s - m, board.rows * s + m)
    cover[~ok] = 0.0
    refl = in_sq * pattern + (1.0 - in_sq)
    z = np.where(cover >= 1.0, z, np.nan)
    return refl, cover, z


def render_board_banded(rays: _CamRays, board: Board, R_cam_board: np.ndarray, t_cam_board: np.ndarray,
                        texture: tuple[np.ndarray, int, float] | None = None, band_px: int = 2_000_000):
    """:func:`render_board` in bands of rows (bounded memory for 4K cameras); float32 outputs."""
    H, W = rays.x.shape
    if texture is not None or H * W <= band_px:
        return tuple(a.astype(np.float32) for a in render_board(rays, board, R_cam_board, t_cam_board, texture=texture))
    out = [np.empty((H, W), np.float32) for _ in range(3)]
    step = max(1, band_px // W)
    for a in range(0, H, step):
        b = min(H, a + step)
        for o, r in zip(out, render_board(rays.band(a, b), board, R_cam_board, t_cam_board)):
            o[a:b] = r
    return tuple(out)


def _smooth_field(rng: np.random.Generator, shape: tuple[int, int], cells: float = 4.0) -> np.ndarray:
    """A smooth random field in [-1, 1] varying over ~``cells`` periods across the image's longer
    side (illumination and heating non-uniformity: few cells; background texture: many)."""
    H, W = shape
    n = max(H, W)
    small = rng.standard_normal((max(2, int(round(cells * H / n)) + 1), max(2, int(round(cells * W / n)) + 1)))
    f = cv2.resize(small, (W, H), interpolation=cv2.INTER_CUBIC)
    return (f / max(1e-9, float(np.abs(f).max()))).astype(np.float32)


# ---------------------------------------------------------------------- poses
def sample_board_poses(rig: Rig, board: Board, n_poses: int, rng: np.random.Generator,
                       depth_range: tuple[float, float] = DEPTH_RANGE_M,
                       max_tilt_deg: float = 55.0) -> list[tuple[np.ndarray, np.ndarray]]:
    """Board poses ``(R_rig_board, t_rig_board)`` spread over ``depth_range`` (stratified) with
    tilts, each chosen (by rejection sampling) so that as many cameras as possible see the whole
    board with a margin of one square."""
    ref = rig.depth() if rig.depth_camera else rig.cameras[0]
    s = board.square_size
    # outer corners of the squares, one square beyond: must be inside every image
    cx, cy = (board.columns - 1) * s / 2, (board.rows - 1) * s / 2
    outline = np.array([[-2 * s, -2 * s, 0], [(board.columns + 1) * s, -2 * s, 0],
                        [(board.columns + 1) * s, (board.rows + 1) * s, 0], [-2 * s, (board.rows + 1) * s, 0]])
    centre_board = np.array([cx, cy, 0.0])
    corners = board.object_points()
    # aim at the region all cameras look at: the mean of camera axes' points at each depth
    zs = depth_range[0] + (np.arange(n_poses) + rng.uniform(0.15, 0.85, n_poses)) / n_poses * (depth_range[1] - depth_range[0])
    rng.shuffle(zs)
    by_width = sorted(rig.cameras, key=lambda c: _fov_tan(c)[0])
    poses = []
    for z in zs:
        best, best_score = None, -1.0
        for attempt in range(400):
            # always some tilt: a narrow camera's principal point (and so its rotation) is only
            # determined by the perspective of tilted boards
            tilt = max_tilt_deg * (0.35 + 0.65 * rng.uniform())
            phi = rng.uniform(0, 2 * np.pi)
            R = (_rot("z", rng.uniform(-12, 12)) @ _rot("x", tilt * np.sin(phi)) @ _rot("y", tilt * np.cos(phi)))
            # centre: on the ray of a pixel near the middle of one camera (narrowest first,
            # so that the narrow cameras get most of the board views), at rig depth z
            anchor = by_width[attempt % len(by_width)]
            frac = 0.3 * (1.0 - attempt / 400)
            px = np.array([[anchor.width * (0.5 + rng.uniform(-frac, frac)),
                            anchor.height * (0.5 + rng.uniform(-frac, frac))]])
            o, d = anchor.rays_rig(px)
            p = o + d[0] * (z - o[2]) / max(d[0, 2], 1e-3)
            t = p - R @ centre_board
            X = outline @ R.T + t
            Xc = corners @ R.T + t
            score = 0.0
            for c in rig.cameras:
                uv, zc = c.project(X)
                vis = bool(np.all(zc > 0.05) and np.all(c.in_image(uv, margin=2)))
                if vis:  # squares of at least MIN_SQUARE_PX: detectors misplace tinier ones
                    g = c.project(Xc)[0].reshape(board.rows, board.columns, 2)
                    vis = min(np.linalg.norm(np.diff(g, axis=0), axis=2).min(),
                              np.linalg.norm(np.diff(g, axis=1), axis=2).min()) >= MIN_SQUARE_PX
                w = 2.0 if c is ref else 1.0
                score += w * vis
            if score > best_score:
                best, best_score = (R, t), score
            if score >= len(rig.cameras) + 1:
                break
        poses.append(best)
    return poses


# ---------------------------------------------------------------------- shading per modality
def _shade(kind: str, refl: np.ndarray, cover: np.ndarray, z: np.ndarray, cam: Camera,
           rng: np.random.Generator, bands: int) -> np.ndarray:
    H, W = refl.shape
    shade = 1.0 + 0.08 * _smooth_field(rng, (H, W), 2.0)
    if kind == "visible":
        albedo = 0.06 + 0.80 * refl                    # toner black 6 %, paper 86 %
        img = albedo * 215.0 * shade
        bg = 70.0 + 30.0 * _smooth_field(rng, (H, W), 40.0)
        img = cover * img + (1.0 - cover) * bg
        img = cv2.GaussianBlur(img.astype(np.float32), (0, 0), 0.6)
        tint = np.array([1.0, 0.97, 0.90], np.float32)
        out = img[..., None] * tint + 1.5 * rng.standard_normal((H, W, 3), dtype=np.float32)
        return np.clip(np.round(out), 0, 255).astype(np.uint8)
    if kind == "infrared":
        zz = np.nan_to_num(z, nan=1.0)
        falloff = (0.6 / np.clip(zz, 0.25, 3.0)) ** 2
        img = (60.0 + 1400.0 * refl) * falloff * shade
        bg = 25.0 + 10.0 * _smooth_field(rng, (H, W), 15.0)
        img = cover * img + (1.0 - cover) * bg
        img = cv2.GaussianBlur(img, (0, 0), 0.7)
        img = img + rng.normal(0.0, 1.0, img.shape) * (2.0 + 0.4 * np.sqrt(np.maximum(img, 0)))
        return np.clip(np.round(img), 0, 65535).astype(np.uint16)
    if kind == "thermal":
        # heated board: printed (black) squares absorb the heat lamp -> warm; paper cooler
        temp = 26.0 + 2.2 * (1.0 - refl) + 0.4 * _smooth_field(rng, (H, W), 2.0)
        bg = 21.5 + 0.8 * _smooth_field(rng, (H, W), 12.0)
        img = cover * temp + (1.0 - cover) * bg
        img = cv2.GaussianBlur(img, (0, 0), 1.3)
        img = img + rng.normal(0.0, 0.07, img.shape)  # NETD ~ 70 mK
        return img.astype(np.float32)
    # hyperspectral: reflectance cube (H, W, B)
    gains = np.linspace(0.55, 1.0, bands)
    albedo = 0.05 + 0.75 * refl
    bg = 0.25 + 0.1 * _smooth_field(rng, (H, W), 6.0)
    base = cover * albedo * shade + (1.0 - cover) * bg
    base = cv2.GaussianBlur(base, (0, 0), 0.7)
    cube = base[..., None].astype(np.float32) * gains.astype(np.float32)
    cube += 0.012 * rng.standard_normal((H, W, bands), dtype=np.float32)
    return cube


def _n_bands(cam: Camera, bands: int | None) -> int:
    """Bands written for a hyperspectral camera: ``bands`` if given, else the camera's band count
    capped at 8 -- a calibration needs geometry, not spectra, and 100-band cubes of 18 poses
    would weigh half a gigabyte."""
    if bands:
        return int(bands)
    b = cam.extra.get("bands", 8)
    n = len(b) if isinstance(b, (list, tuple)) else int(b or 8)
    return max(1, min(n, 8))


_SUFFIX = {"visible": ".png", "infrared": ".png", "thermal": ".tif", "hyperspectral": ".npy"}


def _write(path: Path, img: np.ndarray) -> None:
    s = path.suffix.lower()
    if s == ".png":
        write_png(path, img)
    elif s == ".tif":
        write_tiff(path, img)
    else:
        np.save(path, img)


# ---------------------------------------------------------------------- the session
def write_calibration_session(rig: Rig, folder: str | Path, seed: int = 0, n_poses: int = 18,
                              progress: Reporter | None = None, board: Board | None = None,
                              overwrite: bool = False, bands: int | None = None,
                              tof_bias_mm: tuple[float, float] = (3.0, 2.0),
                              tof_noise_mm: float = 1.0) -> Path:
    """Render a synthetic capture session of ``rig`` into ``folder`` (built under a temporary name,
    moved into place when complete) and return ``folder``.

    ``board`` defaults to :func:`choose_board`. ``bands`` of hyperspectral cameras defaults to the
    camera's ``extra["bands"]`` or 8. Per pose, the ToF bias is drawn from
    N(``tof_bias_mm[0]``, ``tof_bias_mm[1]``) mm; pixel noise N(0, ``tof_noise_mm``) mm.
    Files: ``pose_NN/<camera>.png|.tif|.npy``, ``pose_NN/depth.png`` (uint16 depth units),
    ``session.json``, ``truth.json``.
    """
    progress = ensure_reporter(progress)
    rng = np.random.default_rng(seed)
    board = board or choose_board(rig)
    folder = Path(folder)
    poses = sample_board_poses(rig, board, n_poses, rng)
    texture = board_texture(board) if board.type != "chessboard" else None
    rays: dict[str, _CamRays] = {}
    truth: dict[str, Any] = {"rig": rig.to_dict(), "board": board.to_dict(), "seed": seed,
                             "board_poses": {}, "tof_bias_mm": {}}
    with atomic_output_dir(folder, overwrite=overwrite) as tmp:
        with progress.stage("ray tables", 0.0):
            for i, cam in enumerate(rig.cameras):
                rays[cam.name] = _CamRays(cam)
                progress(0.1 * (i + 1) / len(rig.cameras), f"ray table {cam.name}")
        for k, (R_rig_board, t_rig_board) in enumerate(poses):
            name = f"pose_{k + 1:02d}"
            pdir = tmp / name
            pdir.mkdir()
            bias = float(rng.normal(*tof_bias_mm))
            truth["board_poses"][name] = {"R_rig_board": R_rig_board.tolist(), "t_rig_board": t_rig_board.tolist()}
            for cam in rig.cameras:
                R_cam_board = cam.R_cam_rig @ R_rig_board
                t_cam_board = cam.R_cam_rig @ t_rig_board + cam.t_cam_rig
                refl, cover, z = render_board_banded(rays[cam.name], board, R_cam_board, t_cam_board, texture)
                kind = _kind(cam.modality)
                nb = _n_bands(cam, bands)
                img = _shade(kind, refl, cover, z, cam, rng, nb)
                _write(pdir / f"{cam.name}{_SUFFIX[kind]}", img)
                if cam.name == rig.depth_camera:
                    # ToF depth: z of the board in the depth camera's frame, biased, noisy, quantised
                    d_m = z + (bias + rng.normal(0.0, tof_noise_mm, z.shape)) / 1000.0
                    units = np.where(np.isfinite(d_m), np.round(d_m / rig.depth_scale), 0)
                    _write(pdir / "depth.png", np.clip(units, 0, 65535).astype(np.uint16))
                    truth["tof_bias_mm"][name] = bias
            progress(0.1 + 0.9 * (k + 1) / len(poses), f"rendered {name}")
        session: dict[str, Any] = {"board": board.to_dict()}
        if rig.depth_camera:
            session["depth"] = {"camera": rig.depth_camera, "scale": rig.depth_scale}
        session["cameras"] = {c.name: {"modality": c.modality, **{k: c.extra[k] for k in ("units", "bands")
                                                                   if k in c.extra}} for c in rig.cameras}
        session["review"] = {}
        atomic_write_text(tmp / SESSION_FILE, json.dumps(session, indent=2) + "\n")
        atomic_write_text(tmp / TRUTH_FILE, json.dumps(truth, indent=2) + "\n")
    return folder


def read_truth(folder: str | Path) -> dict[str, Any]:
    """``truth.json`` of a synthetic session: ``rig`` (a :class:`Rig`), ``board_poses``
    {pose: (R_rig_board, t_rig_board)}, ``tof_bias_mm`` {pose: mm}."""
    d = json.loads((Path(folder) / TRUTH_FILE).read_text(encoding="utf-8"))
    return {
        "rig": Rig.from_dict(d["rig"]),
        "board": Board.from_dict(d["board"]),
        "board_poses": {k: (np.asarray(v["R_rig_board"]), np.asarray(v["t_rig_board"]))
                        for k, v in d["board_poses"].items()},
        "tof_bias_mm": {k: float(v) for k, v in d["tof_bias_mm"].items()},
    }


def example_rig() -> Rig:
    """A small rig in the paper's geometry for tests that must not depend on the demo: a wide
    infrared/depth camera (rig frame), a wide RGB camera, narrow thermal and hyperspectral
    cameras converging at ~0.75 m."""
    def K(f, w, h, dx=0.0, dy=0.0):
        return [[f, 0, (w - 1) / 2 + dx], [0, f * 1.001, (h - 1) / 2 + dy], [0, 0, 1]]

    def look_at(centre, target=(0.0, 0.0, 0.75), roll_deg=0.0):
        """R_cam_rig, t_cam_rig of a camera at ``centre`` (rig frame) looking at ``target``."""
        c = np.asarray(centre, float)
        z = np.asarray(target, float) - c
        z /= np.linalg.norm(z)
        x = np.cross([0.0, 1.0, 0.0], z)
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        R = _rot("z", roll_deg) @ np.stack([x, y, z])
        return R, -R @ c

    cams = [Camera("ir", "infrared", 640, 576, K(504.0, 640, 576, 3.0, -4.0), [0.09, -0.05, 0.0005, -0.0003, 0.0])]
    R, t = look_at([0.032, -0.002, -0.004], (0.0, 0.0, 2.0), 0.4)
    cams.append(Camera("rgb", "visible", 1280, 720, K(610.0, 1280, 720, -6.0, 5.0), [0.08, -0.1, -0.0004, 0.0002, 0.03], R, t))
    R, t = look_at([-0.09, 0.04, 0.01], (0.0, 0.0, 0.75), -0.8)
    cams.append(Camera("thermal", "thermal", 640, 480, K(900.0, 640, 480, 4.0, 2.0), [-0.12, 0.2, 0.0, 0.0, 0.0], R, t))
    R, t = look_at([0.10, 0.05, 0.012], (0.0, 0.0, 0.75), 1.1)
    cams.append(Camera("hyperspectral", "hyperspectral", 256, 256, K(420.0, 256, 256, 1.5, -2.0), [-0.05, 0.02, 0, 0, 0], R, t,
                       extra={"bands": [400.0 + 600.0 * k / 7 for k in range(8)]}))  # 8 band centres, nm
    return Rig(cams, "ir", 0.001, np.array([-0.5, -0.5, 0.3]), np.array([0.5, 0.5, 1.2]))
