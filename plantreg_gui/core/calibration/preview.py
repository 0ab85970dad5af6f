"""Display thumbnails of calibration images and detection with a thumbnail (Qt-free).

:func:`detect_with_thumbnail` is what the wizard runs per image in its worker process (see
:mod:`plantreg_gui.core.jobs.process_job`): reading, detecting and shrinking an image all happen
there, so the GUI process only receives the detection and a 112-pixel thumbnail.
"""

from __future__ import annotations

import numpy as np

from ..progress import Reporter
from .detect import DetectOptions, Detection, detect_view


def to_display(img: np.ndarray) -> np.ndarray:
    """Any image (H, W) / (H, W, C) of any dtype -> uint8 (H, W) or (H, W, 3) for display.

    Non-8-bit images (16-bit IR, float thermal) are stretched between the 1st and 99th
    percentile; multi-band cubes show their mean band.
    """
    a = np.asarray(img)
    if a.ndim == 3 and a.shape[2] not in (3, 4):
        a = a.astype(np.float32).mean(axis=2)
    if a.ndim == 3 and a.shape[2] == 4:
        a = a[:, :, :3]
    if a.dtype == np.uint8:
        return np.ascontiguousarray(a)
    f = a.astype(np.float32)
    finite = np.isfinite(f)
    if not finite.any():
        return np.zeros(f.shape, np.uint8)
    lo, hi = np.percentile(f[finite], [1, 99])
    if not hi > lo:
        hi = lo + 1.0
    out = np.clip((f - lo) / (hi - lo) * 255.0, 0, 255)
    out[~finite] = 0
    return out.astype(np.uint8)


def thumbnail(img: np.ndarray, size: int = 120) -> np.ndarray:
    """uint8 display thumbnail whose longer side is ``size`` pixels."""
    import cv2

    d = to_display(img)
    h, w = d.shape[:2]
    s = size / max(h, w)
    if s < 1:
        d = cv2.resize(d, (max(1, round(w * s)), max(1, round(h * s))), interpolation=cv2.INTER_AREA)
    return np.ascontiguousarray(d)


def detect_with_thumbnail(session, pose: str, camera: str, options: DetectOptions | None = None,
                          size: int = 112, progress: Reporter | None = None) -> tuple[Detection, np.ndarray | None]:
    """:func:`~.detect.detect_view` of (``pose``, ``camera``) and a ``size``-pixel display
    thumbnail of the image (None if it has none). Unreadable images raise ``InputError``."""
    from ..io.imageio import read_image

    p = session.pose(pose)
    path = p.images.get(camera)
    img = read_image(path) if path is not None else None
    det = detect_view(session, p, camera, options, image=img)
    return det, (thumbnail(img, size) if img is not None else None)
