"""Where the board has been in a camera's view: the coverage map of the corner review (page 3),
from the found boards' outlines (the convex hulls of their corners)."""

from __future__ import annotations

import cv2
import numpy as np


def coverage_map(detections, camera: str, excluded: set, max_side: int = 240) -> tuple[np.ndarray, tuple[int, int]] | None:
    """Count per (downscaled) pixel of how many used board views of ``camera`` cover it.

    Returns ``(counts (h, w) int32, (W, H) image size)`` or None without any found board. The
    board area of a view is the convex hull of its detected corners.
    """
    dets = [d for (p, c), d in detections.items()
            if c == camera and d.status == "found" and d.corners is not None and (p, c) not in excluded]
    if not dets:
        return None
    W, H = dets[0].image_size
    s = max_side / max(W, H)
    w, h = max(1, round(W * s)), max(1, round(H * s))
    acc = np.zeros((h, w), np.int32)
    for d in dets:
        hull = cv2.convexHull(np.asarray(d.corners, np.float32).reshape(-1, 1, 2) * s)
        m = np.zeros((h, w), np.uint8)
        cv2.fillConvexPoly(m, np.round(hull).astype(np.int32), 1)
        acc += m
    return acc, (W, H)


def coverage_image(acc: np.ndarray) -> np.ndarray:
    """Heat map RGB (h, w, 3): never-covered regions striped dark red, covered ones viridis."""
    top = max(int(acc.max()), 1)
    norm = (np.clip(acc / top, 0, 1) * 255).astype(np.uint8)
    rgb = cv2.cvtColor(cv2.applyColorMap(norm, cv2.COLORMAP_VIRIDIS), cv2.COLOR_BGR2RGB)
    yy, xx = np.mgrid[0:acc.shape[0], 0:acc.shape[1]]
    stripes = ((xx + yy) // 6) % 2 == 0
    empty = acc == 0
    rgb[empty & stripes] = (150, 30, 30)
    rgb[empty & ~stripes] = (90, 20, 20)
    return rgb


def empty_regions(acc: np.ndarray) -> list[str]:
    """Names of the 3 x 3 image regions less than a quarter covered."""
    h, w = acc.shape
    names = [["top-left", "top", "top-right"], ["left", "centre", "right"],
             ["bottom-left", "bottom", "bottom-right"]]
    out = []
    for i in range(3):
        for j in range(3):
            cell = acc[i * h // 3:(i + 1) * h // 3, j * w // 3:(j + 1) * w // 3]
            if cell.size and (cell > 0).mean() < 0.25:
                out.append(names[i][j])
    return out
