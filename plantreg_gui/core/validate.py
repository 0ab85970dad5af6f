"""Validation of user files, in one place: JSON value types named by their key path, camera
names, and the physical sanity bounds of a rig (documented in ``docs/errors.md``).

Every check raises ``ValueError`` with a message that starts with the key path
(``cameras[2].width must be a positive integer, got true``); the loaders turn it into an
:class:`~plantreg_gui.core.errors.InputError` naming the file.

Sanity bounds of a camera (a rig that breaks one cannot describe a real camera, and registering
with it would give one value for every pixel, or none):

* every number finite;
* ``width``, ``height``: whole numbers 1 .. :data:`MAX_SIDE`;
* ``K`` = ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``: no skew (OpenCV's camera model, which
  plantreg uses, ignores ``K[0][1]``: a rig with skew would be registered as if it had none, so
  it is refused), focal lengths between :data:`FOCAL_MIN_FACTOR` and :data:`FOCAL_MAX_FACTOR`
  times the image's larger side, ``fx / fy`` within :data:`MAX_ASPECT` either way, the principal
  point within the image extended by its own size on every side;
* ``dist``: 4, 5, 8, 12 or 14 coefficients whose radial mapping keeps increasing inside the
  image's inscribed circle (about the principal point) and scales radii by at most
  :data:`MAX_DISTORTION_SCALE` either way out to the farthest corner (fitted polynomials may
  turn in the corners, where boards rarely reach: accepted, see :func:`check_distortion`) (a mapping that folds back shows one scene point
  at two radii; one that shrinks or stretches the image more is not a lens);
* ``R``: a rotation (orthonormal within :data:`ROTATION_TOL`, determinant +1);
* ``t``: at most :data:`MAX_TRANSLATION_M` metres from the depth camera (a phenotyping rig fits
  in a room; 1e308 overflows every computation).

Camera names: the one rule of :func:`camera_name` and :func:`unique_names` (docs/errors.md,
"Camera names").
"""

from __future__ import annotations

import json
import math
import re
from typing import Any

import numpy as np

MAX_SIDE = 1 << 16
FOCAL_MIN_FACTOR = 0.05
FOCAL_MAX_FACTOR = 100.0
MAX_ASPECT = 4.0
MAX_DISTORTION_SCALE = 4.0
ROTATION_TOL = 1e-4
MAX_TRANSLATION_M = 100.0
MAX_NAME_LEN = 64
DIST_LENGTHS = (0, 4, 5, 8, 12, 14)


def show(value: Any, limit: int = 40) -> str:
    """A JSON value as the user wrote it (``true``, ``null``, ``"x"``), shortened."""
    try:
        s = json.dumps(value, allow_nan=True)
    except (TypeError, ValueError):
        s = repr(value)
    return s if len(s) <= limit else s[: limit - 3] + "..."


def is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def number(v: Any, key: str, *, positive: bool = False, finite: bool = True) -> float:
    if not is_number(v):
        raise ValueError(f"{key} must be a number, got {show(v)}")
    f = float(v)
    if finite and not math.isfinite(f):
        raise ValueError(f"{key} must be a finite number, got {show(v)}")
    if positive and not f > 0:
        raise ValueError(f"{key} must be positive, got {show(v)}")
    return f


def positive_int(v: Any, key: str, maximum: int | None = None) -> int:
    if not is_number(v) or not math.isfinite(float(v)) or float(v) != int(v) or int(v) <= 0:
        raise ValueError(f"{key} must be a positive integer, got {show(v)}")
    if maximum is not None and int(v) > maximum:
        raise ValueError(f"{key} must be at most {maximum}, got {show(v)}")
    return int(v)


def string(v: Any, key: str) -> str:
    if not isinstance(v, str):
        raise ValueError(f"{key} must be a string, got {show(v)}")
    return v


def number_array(v: Any, key: str, shape: tuple[int, ...] | None = None, what: str = "") -> np.ndarray:
    """A (nested) list of finite numbers of the given shape -> float64 array."""
    def walk(x: Any, path: str) -> None:
        if isinstance(x, list):
            for i, y in enumerate(x):
                walk(y, f"{path}[{i}]")
        elif not is_number(x):
            raise ValueError(f"{path} must be a number, got {show(x)}")
        elif not math.isfinite(float(x)):
            raise ValueError(f"{path} must be finite, got {show(x)}")

    if not isinstance(v, list):
        raise ValueError(f"{key} must be a list{what}, got {show(v)}")
    walk(v, key)
    try:
        a = np.asarray(v, dtype=np.float64)
    except ValueError:
        raise ValueError(f"{key} must be a regular list{what} (rows of equal length)") from None
    if shape is not None and a.shape != shape:
        want = " x ".join(map(str, shape)) if len(shape) > 1 else f"{shape[0]} numbers"
        raise ValueError(f"{key} must be {want}{what}, got shape {' x '.join(map(str, a.shape)) or 'scalar'}")
    return a


# ---------------------------------------------------------------------- camera names
#: Characters no camera name may hold, and why: a camera's name becomes part of its output files'
#: names (``cases/<name>.png``), of PLY property names and of command lines.
FORBIDDEN_NAME_CHARS = {
    "/": "a folder separator", "\\": "a folder separator on Windows",
    ":": "a drive separator on Windows (and shown as '/' by macOS)",
    "*": "a wildcard (a shell would expand cases/*.png-like names to other cameras' files; Windows file "
         "names cannot hold it)",
    "?": "a wildcard (a shell would expand it to other cameras' files; Windows file names cannot hold it)",
    '"': "a quote Windows file names cannot hold", "<": "a shell redirection Windows file names cannot hold",
    ">": "a shell redirection Windows file names cannot hold", "|": "a shell pipe Windows file names cannot hold",
}
#: Names Windows reserves for devices (``cases/CON.png`` cannot be made or copied there).
WINDOWS_DEVICE_NAMES = {"CON", "PRN", "AUX", "NUL", *(f"COM{i}" for i in range(1, 10)), *(f"LPT{i}" for i in range(1, 10))}
_RULE = "camera names are 1 to 64 ASCII characters without / \\ : * ? \" < > |"


def file_stem(name: str) -> str:
    """A camera name as output files spell it (letters, digits, ``_ - .``; the rest becomes ``_``)."""
    s = re.sub(r"[^A-Za-z0-9_.-]", "_", str(name))
    return s or "camera"


def camera_name(v: Any, key: str) -> str:
    """The one camera-name rule (rig, calibration session, recording, outputs): a string of 1 to
    :data:`MAX_NAME_LEN` printable ASCII characters without :data:`FORBIDDEN_NAME_CHARS`, not
    starting with ``.`` (hidden output files) or ``-`` (read as an option: ``--target -x``), no
    leading or trailing space. Non-ASCII is refused: outputs spell such letters as ``_``, and one
    letter has two Unicode spellings that look the same (``ä`` precomposed, or ``a`` + combining
    diaeresis), so two names could look equal and differ, or differ only on another system."""
    if not isinstance(v, str):
        raise ValueError(f"{key} must be a string (the camera's name), got {show(v)}")
    if not v:
        raise ValueError(f"{key} must not be empty")
    if len(v) > MAX_NAME_LEN:
        raise ValueError(f"{key} {show(v, 24)} is {len(v)} characters long; {_RULE}")
    bad = next((c for c in v if not " " <= c <= "~" or c in FORBIDDEN_NAME_CHARS), None)
    if bad is not None:
        if bad in FORBIDDEN_NAME_CHARS:
            why = f"holds {bad!r}, {FORBIDDEN_NAME_CHARS[bad]}"
        elif ord(bad) < 32 or ord(bad) == 127:
            why = f"holds the control character U+{ord(bad):04X}"
        else:
            why = (f"holds the non-ASCII character {bad!r} (U+{ord(bad):04X}): output file and PLY property names "
                   "would spell it '_', and one letter has several Unicode spellings that look the same")
        raise ValueError(f"{key} {show(v)} {why}; {_RULE}")
    if file_stem(v).split(".")[0].upper() in WINDOWS_DEVICE_NAMES:
        raise ValueError(f"{key} {show(v)} is a device name Windows reserves (its output files, e.g. "
                         f"cases/{file_stem(v)}.png, could not be copied there); {_RULE}")
    if v in (".", "..") or v[0] in ".-" or v != v.strip():
        why = ("starts with '.' (its output files would be hidden)" if v[0] == "." else
               "starts with '-' (it would be read as an option on the command line)" if v[0] == "-" else
               "has a leading or trailing space")
        raise ValueError(f"{key} {show(v)} {why}; {_RULE}")
    return v


def unique_names(names: list[str], key: str = "cameras") -> None:
    """Camera names must differ also ignoring case and the characters outputs replace by ``_``."""
    seen: dict[str, str] = {}
    for n in names:
        k = file_stem(n).lower()
        if k in seen:
            other = seen[k]
            if other == n:
                why = "repeated"
            elif other.lower() == n.lower():
                why = ("they differ only in case: their output files would be one file on the case-insensitive file "
                       "systems of Windows and macOS")
            else:
                why = f"output file names spell both '{file_stem(n)}' (characters other than letters, digits, " \
                      "'_', '-' and '.' become '_')"
            raise ValueError(f"{key}: names {show(other)} and {show(n)} clash ({why}); camera names must be unique")
        seen[k] = n


# ---------------------------------------------------------------------- rig sanity
def check_intrinsics(K: np.ndarray, width: int, height: int, key: str) -> None:
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    if K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
        raise ValueError(f"{key}.K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], got {show(K.tolist(), 80)}")
    if K[0, 1] != 0:
        raise ValueError(f"{key}.K has skew (K[0][1] = {K[0, 1]:g}); OpenCV's camera model, which plantreg uses, "
                         "ignores it, so registration would be wrong: set it to 0 or recalibrate without skew")
    side = max(width, height)
    for nm, f in (("fx", fx), ("fy", fy)):
        if not f > 0:
            raise ValueError(f"{key}.K: {nm} must be positive, got {f:g}")
        if not FOCAL_MIN_FACTOR * side <= f <= FOCAL_MAX_FACTOR * side:
            raise ValueError(f"{key}.K: {nm} = {f:g} px is implausible for a {width}x{height} image (the sanity "
                             f"bound is {FOCAL_MIN_FACTOR:g} to {FOCAL_MAX_FACTOR:g} times the larger side, "
                             f"{FOCAL_MIN_FACTOR * side:g} to {FOCAL_MAX_FACTOR * side:g} px)")
    if not 1.0 / MAX_ASPECT <= fx / fy <= MAX_ASPECT:
        raise ValueError(f"{key}.K: fx / fy = {fx / fy:.3g} is implausible (bound {1 / MAX_ASPECT:g} to {MAX_ASPECT:g})")
    if not (-width <= cx <= 2 * width and -height <= cy <= 2 * height):
        raise ValueError(f"{key}.K: principal point ({cx:g}, {cy:g}) lies far outside the {width}x{height} image "
                         "(swapped width and height, or cx/cy in the wrong place?)")


def radial_scale(dist: np.ndarray, r: np.ndarray) -> np.ndarray:
    """OpenCV's radial factor (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6) at
    normalised radii ``r`` (N,)."""
    k = np.zeros(8)
    d = np.asarray(dist, dtype=np.float64).ravel()
    k[: min(8, d.size)] = d[:8]
    k1, k2, p1, p2, k3, k4, k5, k6 = k
    r2 = r * r
    with np.errstate(over="ignore", invalid="ignore"):
        return (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))


def check_distortion(dist: np.ndarray, K: np.ndarray, width: int, height: int, key: str) -> None:
    """Distortion sanity (normalised radii r, distorted radius r_d = r * radial_scale(r)):

    * inside the image's inscribed circle (the largest circle about the principal point that
      lies in the image) r_d must increase with r -- no fold where every direction has data;
    * out to the farthest image corner (or to where a fitted polynomial turns beyond that
      circle) the scale r_d / r must stay within 1/MAX_DISTORTION_SCALE .. MAX_DISTORTION_SCALE.

    Fitted polynomials often turn in the image corners, where the board never reached; that is
    accepted (docs/errors.md), a fold inside the inscribed circle is not."""
    if dist.size not in DIST_LENGTHS:
        raise ValueError(f"{key}.dist has {dist.size} coefficients (OpenCV takes 4, 5, 8, 12 or 14)")
    if not np.any(dist):
        return
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    xs = np.array([-0.5 - cx, width - 0.5 - cx]) / fx
    ys = np.array([-0.5 - cy, height - 0.5 - cy]) / fy
    rd_corner = float(np.max(np.hypot(xs[:, None], ys[None, :])))
    inside = cx > -0.5 and cx < width - 0.5 and cy > -0.5 and cy < height - 0.5
    rd_in = float(min(np.abs(xs).min(), np.abs(ys).min())) if inside else 0.0
    r = np.linspace(0.0, MAX_DISTORTION_SCALE * rd_corner, 8001)[1:]
    s = radial_scale(dist, r)
    with np.errstate(all="ignore"):  # coefficients like 1e308 overflow: non-finite radii are refused below
        rd = r * s
        ok = np.isfinite(rd)
        down = np.flatnonzero(~ok[1:] | ~ok[:-1] | (np.diff(rd) <= 0))
    first_fold = int(down[0]) if down.size else len(r) - 1
    reach_in = np.flatnonzero(ok & (rd >= rd_in))
    if rd_in > 0 and (not reach_in.size or first_fold < reach_in[0]):
        at = rd[first_fold] if np.isfinite(rd[first_fold]) else 0.0
        raise ValueError(f"{key}.dist {show(dist.tolist(), 60)} folds the image: the distorted radius stops "
                         f"increasing at {100 * at / rd_corner:.0f} % of the way to the image corner, inside the "
                         "image's inscribed circle, so points beyond it would be imaged twice")
    reach_corner = np.flatnonzero(ok & (rd >= rd_corner))
    end = min(first_fold, int(reach_corner[0]) if reach_corner.size else len(r) - 1) + 1
    seg_s, seg_rd = s[:end], rd[:end]
    bad_scale = ~(np.isfinite(seg_s) & (seg_s >= 1 / MAX_DISTORTION_SCALE) & (seg_s <= MAX_DISTORTION_SCALE))
    if bad_scale.any():
        i = int(np.argmax(bad_scale))
        raise ValueError(f"{key}.dist {show(dist.tolist(), 60)} scales the image radius by {seg_s[i]:.3g} at "
                         f"{100 * min(seg_rd[i] / rd_corner, 1):.0f} % of the way to the image corner; the sanity "
                         f"bound is {1 / MAX_DISTORTION_SCALE:g} to {MAX_DISTORTION_SCALE:g} (wrong coefficients, or "
                         "coefficients of another camera model?)")


def check_rotation(R: np.ndarray, key: str) -> None:
    err = float(np.max(np.abs(R @ R.T - np.eye(3))))
    if err > ROTATION_TOL or np.linalg.det(R) <= 0:
        raise ValueError(f"{key}.R is not a rotation matrix (R R^T differs from the identity by {err:.2g}, "
                         f"det {np.linalg.det(R):.3g}; tolerance {ROTATION_TOL:g}, det must be +1)")


def check_translation(t: np.ndarray, key: str) -> None:
    big = float(np.max(np.abs(t)))
    n = big if big > MAX_TRANSLATION_M else float(np.linalg.norm(t))  # no overflow for 1e308
    if not n <= MAX_TRANSLATION_M:
        raise ValueError(f"{key}.t is {n:.3g} m from the depth camera; the sanity bound is {MAX_TRANSLATION_M:g} m "
                         "(t is in metres: millimetres by mistake?)")


#: depth.scale (metres per depth unit): 1 for depth maps in metres; more is not a depth map. At
#: least a micrometre per unit (65535 units then span 6.5 cm): 1e-300 made every depth 0 m and
#: was reported as "no surface inside the region of interest" against the depth map.
MAX_DEPTH_SCALE = 1000.0
MIN_DEPTH_SCALE = 1e-6


def bounded(v: Any, key: str, lo: float, hi: float, unit: str = "", *, lo_open: bool = False) -> float:
    """The one check of a number that has a physical range: a number (not a boolean or a
    string), finite, ``lo`` <= v <= ``hi`` (``lo_open``: ``lo`` < v). Denormal, vanishing or
    astronomical values of a well-typed key are named here, not later as what they caused."""
    if not is_number(v):
        raise ValueError(f"{key} must be a number{f' ({unit})' if unit else ''}, got {show(v)}")
    f = float(v)
    if not (f > lo if lo_open else f >= lo) or not f <= hi:  # NaN fails too
        low = f"above {lo:g}" if lo_open else f"at least {lo:g}"
        raise ValueError(f"{key} must be {low} and at most {hi:g}{f' ({unit})' if unit else ''}, got {show(v)}")
    return f


def depth_scale(v: Any, key: str) -> float:
    """The one check of a depth scale (metres per depth unit) wherever one is given: the rig's
    ``depth.scale``, a session's, a recording's ``depth_scale`` and the ``--depth-scale`` options:
    a number in [:data:`MIN_DEPTH_SCALE`, :data:`MAX_DEPTH_SCALE`]."""
    return bounded(v, key, MIN_DEPTH_SCALE, MAX_DEPTH_SCALE, "metres per depth unit")


#: Optional per-camera keys of a rig in pixels (``core/registration/mixed.py``): the optical blur
#: (Gaussian sigma) and the expected registration error. Up to :data:`MAX_CAMERA_PX`: a blur of
#: 1e308 px overflowed the mixed-pixel search; -1 or NaN were silently taken as 0.
CAMERA_PX_KEYS = ("blur_px", "registration_px")
MAX_CAMERA_PX = 1000.0


def camera_px_keys(d: dict, key: str) -> None:
    """Check the optional pixel keys (:data:`CAMERA_PX_KEYS`) of a rig's camera entry ``d``."""
    for k in CAMERA_PX_KEYS:
        if k in d and d[k] is not None:
            bounded(d[k], f"{key}.{k}", 0.0, MAX_CAMERA_PX, "pixels")
