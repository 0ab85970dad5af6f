"""Start rigs from what a user knows (``plantreg rig create``): camera models, resolutions, a field
of view or focal length, how each camera's image is turned against the depth camera's, a rough
position -- and the Azure Kinect's factory calibration where the recording carries it.

Camera spec (one ``--camera`` each)::

    NAME=MODALITY,WxH,LENS,rot=0|90|180|270[,at=X,Y,Z]
    LENS: hfov=DEG[,vfov=DEG] | f=PX[,fy=PX] | kinect=CALIBRATION.json | kinect=typical

``rot=A``: the scene appears turned ``A`` degrees anticlockwise in this camera's image compared
with the depth camera's (A = 90: the depth camera's up is this camera's left). ``at``: the
camera's optical centre in the rig (= depth camera) frame, metres (x right, y down, z forward
of the depth camera); default the depth camera's own centre.

The Azure Kinect reader takes the raw calibration JSON (``CalibrationInformation``: what
``k4a_device_get_raw_calibration`` returns and what a k4arecorder MKV carries as its
``calibration.json`` attachment) and converts the depth camera's parameters to a depth mode as
the SDK does (``transformation_get_mode_specific_depth_camera_calibration``: normalised
parameters times the binned sensor size, minus the mode's crop offset, minus half a pixel for
pixel centres at integers). ``kinect=typical`` gives a typical device's lens instead (for
recordings without their device's calibration; fit ``ir:k1`` and the principal point then).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..camera import modality as modalities
from ..camera.camera import Camera
from ..camera.record import CalibrationRecord
from ..camera.rig import Rig
from ..errors import InputError
from ..io.imageio import read_json

#: Azure Kinect depth modes: output size -> (name, binned calibration resolution, crop offset)
KINECT_DEPTH_MODES = {
    (320, 288): ("NFOV_2X2BINNED", (512, 512), (96, 90)),
    (640, 576): ("NFOV_UNBINNED", (1024, 1024), (192, 180)),
    (512, 512): ("WFOV_2X2BINNED", (512, 512), (0, 0)),
    (1024, 1024): ("WFOV_UNBINNED", (1024, 1024), (0, 0)),
}

#: a *typical* Azure Kinect depth lens for ``kinect=typical`` (a recording without its device's
#: calibration): NFOV-unbinned fx = fy = 504, principal point (323.4, 329.8) -- the mean of three
#: published factory calibrations -- and one of them's rational 6-k distortion as OpenCV
#: [k1 k2 p1 p2 k3 k4 k5 k6] (resources/plant3dimagereg/landmark_scripts/make_nominal_rig.py cites them);
#: stored as the SDK's raw normalised parameters (cx, cy, fx, fy of the 1024 x 1024 sensor, 0-cornered)
KINECT_TYPICAL_RAW = ((323.4 + 0.5 + 192) / 1024, (329.8 + 0.5 + 180) / 1024, 504.0 / 1024, 504.0 / 1024)
KINECT_TYPICAL_DIST = (4.7247, 3.2092, 0.0, 0.0, 0.1706, 5.0559, 4.7758, 0.8865)

#: where a datasheet field of view is taken as a pinhole's and the two axes disagree by more than
#: this, the lens is distorted (square pixels assumed) and the user is told
FOV_MISMATCH = 0.03


@dataclass
class CameraSpec:
    """One parsed ``--camera`` item."""

    name: str
    modality: str
    width: int
    height: int
    hfov_deg: float | None = None
    vfov_deg: float | None = None
    fx: float | None = None
    fy: float | None = None
    kinect: Path | None = None
    rot_deg: int = 0
    at: np.ndarray = field(default_factory=lambda: np.zeros(3))


def parse_camera_spec(text: str) -> CameraSpec:
    """``NAME=MODALITY,WxH,LENS,rot=A[,at=X,Y,Z]`` -> :class:`CameraSpec` (see the module doc);
    :class:`InputError` naming the item on any mistake."""
    name, sep, rest = text.partition("=")
    name = name.strip()
    if not sep or not name or not rest:
        raise InputError(f"--camera takes NAME=MODALITY,WxH,LENS,rot=A[,at=X,Y,Z], got '{text}'")

    def bad(msg: str) -> InputError:
        return InputError(f"--camera '{name}': {msg}")

    parts = [p.strip() for p in rest.split(",")]
    if len(parts) < 3:
        raise bad("give MODALITY,WxH and a lens (hfov=DEG, f=PX or kinect=FILE)")
    mod, size, items = parts[0], parts[1], parts[2:]
    if modalities.canonical(mod) not in modalities.names():
        raise bad(f"unknown modality '{mod}' (choose from {', '.join(modalities.names())})")
    w, x, h = size.lower().partition("x")
    try:
        width, height = int(w), int(h)
    except ValueError:
        raise bad(f"size must be WIDTHxHEIGHT in pixels, got '{size}'") from None
    if not x or width <= 0 or height <= 0:
        raise bad(f"size must be WIDTHxHEIGHT in pixels, got '{size}'")
    # "at=X,Y,Z" spans three comma items: numbers without a key belong to the key before them
    kv: dict[str, list[str]] = {}
    last = None
    for it in items:
        k, eq, v = it.partition("=")
        if eq:
            last = k.strip().lower()
            if last in kv:
                raise bad(f"'{last}' given twice")
            kv[last] = [v.strip()]
        elif last is not None:
            kv[last].append(it)
        else:
            raise bad(f"cannot read '{it}'")
    known = {"hfov", "vfov", "f", "fy", "kinect", "rot", "at"}
    for k in kv:
        if k not in known:
            raise bad(f"unknown item '{k}' (choose from {', '.join(sorted(known))})")

    def num(k: str, lo: float, hi: float) -> float | None:
        if k not in kv:
            return None
        if len(kv[k]) != 1:
            raise bad(f"{k} takes one number")
        try:
            v = float(kv[k][0])
        except ValueError:
            raise bad(f"{k} must be a number, got '{kv[k][0]}'") from None
        if not (lo < v < hi):
            raise bad(f"{k} must lie between {lo:g} and {hi:g}, got {v:g}")
        return v

    spec = CameraSpec(name, modalities.canonical(mod), width, height,
                      hfov_deg=num("hfov", 0, 180), vfov_deg=num("vfov", 0, 180), fx=num("f", 0, math.inf),
                      fy=num("fy", 0, math.inf))
    if "kinect" in kv:
        spec.kinect = Path(",".join(kv["kinect"]))
    lenses = [k for k in ("hfov", "f", "kinect") if k in kv]
    if len(lenses) != 1:
        raise bad("give exactly one lens: hfov=DEG[,vfov=DEG], f=PX[,fy=PX] or kinect=CALIBRATION.json")
    if "vfov" in kv and "hfov" not in kv or "fy" in kv and "f" not in kv:
        raise bad("vfov goes with hfov, fy with f")
    if "rot" not in kv:
        raise bad("say how its image is turned against the depth camera's: rot=0, 90, 180 or 270 "
                  "(degrees anticlockwise)")
    try:
        rot = int(kv["rot"][0]) % 360
    except ValueError:
        raise bad(f"rot must be 0, 90, 180 or 270, got '{kv['rot'][0]}'") from None
    if rot % 90 or len(kv["rot"]) != 1:
        raise bad(f"rot must be 0, 90, 180 or 270, got '{','.join(kv['rot'])}' (a rough placement: the fit "
                  "finds the exact angle)")
    spec.rot_deg = rot
    if "at" in kv:
        try:
            at = np.array([float(v) for v in kv["at"]])
        except ValueError:
            raise bad(f"at takes X,Y,Z in metres, got '{','.join(kv['at'])}'") from None
        if at.shape != (3,) or not np.all(np.isfinite(at)) or np.abs(at).max() > 10:
            raise bad(f"at takes X,Y,Z in metres (within 10 m), got '{','.join(kv['at'])}'")
        spec.at = at
    return spec


def R_turned(rot_deg: int) -> np.ndarray:
    """(3, 3) ``R_cam_rig`` of a camera looking along the depth camera's axis whose image shows the
    scene turned ``rot_deg`` anticlockwise: a roll of ``-rot_deg`` about the optical axis (rows =
    the camera's x and y axes in the rig frame)."""
    a = math.radians(-rot_deg)
    c, s = round(math.cos(a)), round(math.sin(a))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def read_kinect_depth_calibration(path: Path, width: int, height: int) -> tuple[np.ndarray, np.ndarray, str]:
    """The Azure Kinect depth camera's ``K`` (3, 3) and OpenCV rational ``dist`` (8,) for the depth
    mode of output size ``width`` x ``height``, from a raw calibration JSON. Returns
    ``(K, dist, mode name)``."""
    mode = KINECT_DEPTH_MODES.get((width, height))
    if mode is None:
        sizes = ", ".join(f"{w}x{h} ({m[0]})" for (w, h), m in KINECT_DEPTH_MODES.items())
        raise InputError(f"no Azure Kinect depth mode gives {width}x{height} images (modes: {sizes})", path)
    if str(path) == "typical":
        name, (bw, bh), (ox, oy) = mode
        cx, cy, fx, fy = KINECT_TYPICAL_RAW
        K = np.array([[fx * bw, 0.0, cx * bw - ox - 0.5], [0.0, fy * bh, cy * bh - oy - 0.5], [0.0, 0.0, 1.0]])
        return K, np.array(KINECT_TYPICAL_DIST), name + ", a typical device's lens, not this one's"
    d = read_json(Path(path), "Azure Kinect calibration")
    try:
        cams = d["CalibrationInformation"]["Cameras"]
    except (KeyError, TypeError):
        raise InputError("not an Azure Kinect raw calibration (no CalibrationInformation.Cameras)", path) from None
    depth = [c for c in cams if isinstance(c, dict) and c.get("Purpose") == "CALIBRATION_CameraPurposeDepth"]
    if len(depth) != 1:
        raise InputError(f"expected one camera with Purpose CALIBRATION_CameraPurposeDepth, found {len(depth)}", path)
    c = depth[0]
    try:
        p = [float(v) for v in c["Intrinsics"]["ModelParameters"]]
        sw, sh = int(c["SensorWidth"]), int(c["SensorHeight"])
    except (KeyError, TypeError, ValueError):
        raise InputError("depth camera entry lacks Intrinsics.ModelParameters or SensorWidth/SensorHeight", path) from None
    if len(p) < 14 or not all(math.isfinite(v) for v in p[:14]):
        raise InputError(f"depth camera has {len(p)} model parameters, expected 14 finite numbers", path)
    if (sw, sh) != (1024, 1024):
        raise InputError(f"depth sensor is {sw}x{sh}, the SDK's depth modes expect 1024x1024", path)
    model = str(c["Intrinsics"].get("ModelType", ""))
    if "Rational6KT" not in model and "BrownConrady" not in model:
        raise InputError(f"lens model '{model}' is not the Brown-Conrady / Rational6KT model this reader knows", path)
    name, (bw, bh), (ox, oy) = mode
    cx, cy, fx, fy = p[0] * bw - ox - 0.5, p[1] * bh - oy - 0.5, p[2] * bw, p[3] * bh
    k1, k2, k3, k4, k5, k6, _codx, _cody, p2, p1 = p[4:14]
    if not (fx > 0 and fy > 0 and 0 < cx < width and 0 < cy < height):
        raise InputError(f"depth intrinsics for {name} are impossible (fx {fx:.1f}, principal point "
                         f"({cx:.1f}, {cy:.1f}) for {width}x{height})", path)
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    return K, np.array([k1, k2, p1, p2, k3, k4, k5, k6]), name


def make_camera(spec: CameraSpec) -> tuple[Camera, list[str]]:
    """The start camera of ``spec`` and warnings about it."""
    warnings: list[str] = []
    dist = np.zeros(5)
    extra: dict[str, Any] = {}
    if spec.kinect is not None:
        K, dist, mode = read_kinect_depth_calibration(spec.kinect, spec.width, spec.height)
        extra["intrinsics_source"] = (f"Azure Kinect factory calibration {spec.kinect} ({mode})"
                                      if str(spec.kinect) != "typical" else f"Azure Kinect {mode}")
        if str(spec.kinect) == "typical":
            warnings.append(f"{spec.name}: a typical Azure Kinect lens, not this device's: free its k1 (fit-rig --free "
                            f"{spec.name}:k1) or, with enough landmarks, its principal point too")
    elif spec.fx is not None:
        fy = spec.fy if spec.fy is not None else spec.fx
        K = np.array([[spec.fx, 0, (spec.width - 1) / 2.0], [0, fy, (spec.height - 1) / 2.0], [0, 0, 1.0]])
        extra["intrinsics_source"] = "focal length given"
    else:
        fx = (spec.width / 2.0) / math.tan(math.radians(spec.hfov_deg) / 2.0)
        fy = fx
        if spec.vfov_deg is not None:
            fy_v = (spec.height / 2.0) / math.tan(math.radians(spec.vfov_deg) / 2.0)
            if abs(fy_v / fx - 1.0) > FOV_MISMATCH:
                warnings.append(
                    f"{spec.name}: {spec.hfov_deg:g} x {spec.vfov_deg:g} degrees gives fx {fx:.0f} but fy {fy_v:.0f} "
                    f"px ({100 * abs(fy_v / fx - 1):.0f} % apart): pixels are square, so the data sheet's field of view "
                    "is not a pinhole's (a distorted lens: its corners see further than a pinhole of the same "
                    f"focal length); fx = fy = {fx:.0f} taken from the horizontal figure")
        K = np.array([[fx, 0, (spec.width - 1) / 2.0], [0, fy, (spec.height - 1) / 2.0], [0, 0, 1.0]])
        extra["intrinsics_source"] = f"data sheet field of view {spec.hfov_deg:g} degrees, pinhole, no distortion"
        warnings.append(
            f"{spec.name}: focal length {fx:.0f} px from the data sheet's field of view (a pinhole without "
            "distortion): a distorted lens's true focal length differs, often by 5-20 %; fit it "
            f"(fit-rig --free {spec.name}:focal, and --prior focal=0.2 if it may be that far off)")
    R = R_turned(spec.rot_deg)
    cam = Camera(spec.name, spec.modality, spec.width, spec.height, K, dist, R, -R @ spec.at, extra)
    return cam, warnings


def create_rig(specs: list[CameraSpec], depth_camera: str, depth_scale: float = 0.001,
               roi: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[Rig, list[str]]:
    """A start rig from camera specs; the depth camera is the rig frame (its ``rot`` must be 0
    and its ``at`` the origin). Returns the rig and the warnings to show."""
    names = [s.name for s in specs]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputError(f"camera '{dup[0]}' is given twice")
    if depth_camera not in names:
        raise InputError(f"--depth-camera '{depth_camera}' is not among the cameras ({', '.join(names)})")
    d = specs[names.index(depth_camera)]
    if d.rot_deg != 0 or np.any(d.at != 0):
        raise InputError(f"the depth camera '{depth_camera}' defines the rig frame: give it rot=0 and no at=")
    from .. import validate

    try:
        depth_scale = validate.depth_scale(depth_scale, "--depth-scale")
    except ValueError as e:
        raise InputError(str(e)) from None
    cams, warnings = [], []
    for s in specs:
        c, w = make_camera(s)
        cams.append(c)
        warnings += w
        if s.name != depth_camera and not np.any(s.at):
            warnings.append(f"{s.name}: no position given (at=X,Y,Z): placed at the depth camera's centre; "
                            "fit-rig starts from PnP where this explains the landmarks badly")
    rig = Rig(cams, depth_camera, depth_scale)
    if roi is not None:
        lo, hi = (np.asarray(v, float) for v in roi)
        if not np.all(hi > lo):
            raise InputError("--roi: every max must be larger than its min")
        rig.roi_min, rig.roi_max = lo, hi
    _check_as_read(rig, specs)
    CalibrationRecord("start", "plantreg rig create", details={"warnings": warnings}).store(rig)
    return rig, warnings


def _check_as_read(rig: Rig, specs: list[CameraSpec]) -> None:
    """Refuse a rig its reader would refuse (``Rig.from_dict``: camera names, sizes, focal lengths,
    positions, the region of interest and their sanity bounds, docs/errors.md) -- one rule for
    what a rig file may hold, whoever writes it -- naming the option that gave the value."""
    import re

    try:
        Rig.from_dict(rig.to_dict())
    except InputError as e:
        def option(m: re.Match) -> str:
            return f"--camera {specs[int(m.group(1))].name!r}: " if int(m.group(1)) < len(specs) else m.group(0)

        text = re.sub(r"cameras\[(\d+)\]\.?", option, e.detail)
        text = re.sub(r"^roi\.?", "--roi: ", text).replace("depth.scale", "--depth-scale")
        raise InputError(text) from None
