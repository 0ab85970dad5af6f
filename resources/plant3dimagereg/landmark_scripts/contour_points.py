"""Candidate landmarks from each image's OWN silhouette: leaf tips and notches.

For one camera image at a time (never across modalities): a plant mask (infrared: depth nearer
than the tray; hyperspectral render: not the blue background; thermal: away from the background
temperature), its outer contours, the contour smoothed along the arc with a Gaussian of
``sigma`` pixels (scaled with the camera's pixel size near the plant, so that the same physical
rounding applies in every camera), and the local extrema of signed curvature: convex tips
(k > 0) and concave notches (k < 0), at sub-pixel positions on the smoothed contour (which lies
slightly inside the leaf at a tip). Pairing the candidates of two cameras is done by the
annotator by eye (pair panels); a coarse silhouette alignment only proposes which candidates to
look at.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter1d

from annotate_view import load


def _near(plant: str) -> np.ndarray:
    d = cv2.medianBlur(load(plant, "depth").astype(np.uint16), 3).astype(np.float64)
    m = ((d > 0) & (d < 1130)).astype(np.uint8)
    return cv2.morphologyEx(m, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))


def frame_mask() -> np.ndarray:
    """The tray's frame in the depth image (the camera never moved): near components of the
    grapevine's depth map that do not reach the image centre, dilated by 2 px."""
    m = _near("01grapevine")
    n, lab, st, _ = cv2.connectedComponentsWithStats(m)
    keep = [i for i in range(1, n) if not np.any(lab[200:380, 220:420] == i)]
    return cv2.dilate(np.isin(lab, keep).astype(np.uint8), np.ones((5, 5), np.uint8))


def plant_mask(plant: str, cam: str) -> np.ndarray:
    """uint8 (H, W) 0/1 plant mask of one camera's image."""
    if cam == "ir":
        m = _near(plant) & (1 - frame_mask())
        n, lab, st, _ = cv2.connectedComponentsWithStats(m)
        keep = [i for i in range(1, n) if st[i, 4] > 300 and np.any(lab[200:380, 220:420] == i)]
        return np.isin(lab, keep).astype(np.uint8)
    if cam == "hyperspectral":
        hs = load(plant, "hyperspectral").astype(np.float32)
        b, g, r = hs[..., 0], hs[..., 1], hs[..., 2]
        # leaves are greener than the dark-blue background: Otsu on (G - B), smoothed a little
        x = cv2.GaussianBlur(np.clip(g - b + 128, 0, 255).astype(np.uint8), (3, 3), 0)
        _, m = cv2.threshold(x, 0, 1, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
        return cv2.morphologyEx(m, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    th = load(plant, "thermal")
    tb = cv2.GaussianBlur(th, (0, 0), 1.5)
    x = np.clip((tb - np.percentile(tb, 1)) / (np.percentile(tb, 99) - np.percentile(tb, 1)) * 255, 0, 255)
    _, m = cv2.threshold(x.astype(np.uint8), 0, 1, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    # the plant is the class that is rarer along the image border
    b = np.concatenate([m[:4].ravel(), m[-4:].ravel(), m[:, :4].ravel(), m[:, -4:].ravel()])
    if b.mean() > 0.5:
        m = 1 - m
    return cv2.morphologyEx(m, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))


def curvature_points(mask: np.ndarray, sigma: float, min_len: int = 60, min_k: float | None = None):
    """(N, 2) sub-pixel (u, v) points, (N,) signed curvature (1/px; > 0 convex tip), (N, 2) unit
    inward normals, at local curvature extrema of the smoothed outer contours."""
    cs, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    min_k = 0.6 / (sigma * 4) if min_k is None else min_k
    P, K, N = [], [], []
    for c in cs:
        c = c.reshape(-1, 2).astype(np.float64)
        if len(c) < min_len:
            continue
        x = gaussian_filter1d(c[:, 0], sigma, mode="wrap")
        y = gaussian_filter1d(c[:, 1], sigma, mode="wrap")
        dx, dy = np.gradient(x), np.gradient(y)
        ddx, ddy = np.gradient(dx), np.gradient(dy)
        k = (dx * ddy - dy * ddx) / np.maximum((dx * dx + dy * dy) ** 1.5, 1e-9)
        # OpenCV outer contours run so that this k is negative at convex corners: flip to tips > 0
        area = 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)
        k = k * (-1 if area > 0 else 1)
        w = max(int(2 * sigma), 2)
        for i in range(len(k)):
            win = np.abs(k[np.arange(i - w, i + w + 1) % len(k)])
            if abs(k[i]) >= min_k and abs(k[i]) == win.max():
                t = np.array([dx[i], dy[i]]) / np.hypot(dx[i], dy[i])
                n = np.array([-t[1], t[0]])
                # inward normal: points into the mask
                q = np.round([x[i] + 2 * n[0], y[i] + 2 * n[1]]).astype(int)
                inside = 0 <= q[1] < mask.shape[0] and 0 <= q[0] < mask.shape[1] and mask[q[1], q[0]]
                P.append((x[i], y[i]))
                K.append(k[i])
                N.append(n if inside else -n)
    return np.array(P).reshape(-1, 2), np.array(K), np.array(N).reshape(-1, 2)
