"""Time-of-flight depth clean-up before meshing: flying-pixel removal and edge-preserving denoising.

Both work on the depth map (H, W) in metres (NaN = no measurement) in the depth camera's own
pixel grid, with windows of neighbouring pixels. "Same surface" is decided by depth alone,
with a tolerance **proportional to the depth** (the pixel footprint grows with depth, and so
does what a surface of a given slope changes in depth from one pixel to the next):
two pixels lie on one surface when ``|z_q - z_p| <= tol_rel * z_p``.

Flying pixels (:func:`flying_pixels`)
-------------------------------------
A ToF pixel whose footprint straddles a depth edge (a leaf over the ground) integrates both
surfaces and reports a depth *between* them: a point floating in the air behind the leaf's
rim. A pixel is flying when

* within ``radius`` pixels (5 x 5 window for radius 2) it has a neighbour **nearer** by more
  than ``jump_rel * z`` *and* one **farther** by more than ``jump_rel * z`` -- it lies between
  two surfaces along the line of sight; and
* at most ``max_support`` of its 8 direct neighbours lie on its own surface (within
  ``jump_rel * z``): it does not belong to a surface of its own (a steep but real surface
  has neighbours along its contour lines).

Pixels with no same-surface neighbour at all (isolated speckle) are flying too. With
``jump_rel`` = 0.01 (1 cm at 1 m, i.e. a jump within ~11 degrees of the line of sight for
the Azure Kinect's 2 mm pixel pitch at 1 m) surfaces up to ~75 degrees steep are never taken
for a jump, even with 1-2 mm noise.

Hole filling (:func:`fill_holes`)
---------------------------------
A ToF pixel whose surface is steep to the line of sight returns too little light and reports
nothing: holes on stem flanks, the pot's side and leaves seen edge-on. Meshed as they are,
those holes cut gaps into thin occluders (a stem) through which a source camera "sees" what the
stem hides, and a target pixel on a hole has no point at all. A hole pixel is filled when, along
one of the four lines through it (row, column, both diagonals), the nearest measured pixels on
*both* sides within ``reach`` pixels lie on one surface: ``|z_a - z_b| <= (i + j) * tol_rel *
min(z_a, z_b)`` for neighbours ``i`` and ``j`` pixels away (the flying-pixel test's per-pixel
jump, summed over the span). Its depth is the linear interpolation between them (the mean over
the lines that qualify); the plane fit below then refines it from its same-surface neighbours.
A hole at a silhouette is filled only along the silhouette (both sides on the surface), never
across it: nothing says where the surface ends. One ambiguous case remains: the corner pixel of a
recess (a gap between leaves) lies on a diagonal of the surrounding surface and takes its depth.

Denoising (:func:`denoise_depth`)
---------------------------------
Each pixel's depth is replaced by a least-squares plane fitted, in image coordinates, to the
pixels of a ``size`` x ``size`` window (default 5 x 5) that lie on the *same surface* as the
centre (``|z_q - z_p| <= tol_rel * z_p``) and are not flying; the plane's value at the centre
is the new depth. Neighbours across a depth edge never enter the fit, so two leaves are never
averaged or bridged; a plane (not a mean) keeps inclined surfaces unbiased and the fit is
exact for a plane seen by a pinhole camera up to second order over the window. With fewer than
``min_support`` same-surface pixels, or when they lie on a line (a stem one pixel wide), the
mean of the same-surface pixels is used, or the pixel is left unchanged when it has fewer than
three. For a 5 x 5 window the random error of a pixel on a plane drops by up to a factor of 5
(the centre value of a 25-point fit has variance sigma^2 / 25).

OpenCV's bilateral filter (``cv2.bilateralFilter``) was measured as an alternative: its range
kernel is a fixed number of metres, so it blurs 1 cm steps at 0.5 m and leaves noise at 1.2 m,
and its Gaussian weights pull edge pixels towards the other surface; the same-surface plane fit
keeps every depth edge exactly.
"""

from __future__ import annotations

import numpy as np


def flying_pixels(depth_m: np.ndarray, jump_rel: float = 0.01, radius: int = 2,
                  max_support: int = 2) -> np.ndarray:
    """Flying (mixed, floating) pixels of a ToF depth map; see the module docstring.

    ``depth_m`` (H, W) metres, NaN or <= 0 = none. Returns (H, W) bool.
    """
    import cv2

    z = np.asarray(depth_m, dtype=np.float32)
    with np.errstate(invalid="ignore"):
        valid = z > 0
    z = np.where(valid, z, np.float32(np.nan))
    H, W = z.shape
    tol = np.float32(jump_rel) * z
    z_lo = np.where(valid, z, np.float32(np.inf))
    z_hi = np.where(valid, z, np.float32(-np.inf))

    def nearest(k: np.ndarray) -> np.ndarray:  # min filter (no measurement ignored)
        return cv2.erode(z_lo, k, borderType=cv2.BORDER_CONSTANT, borderValue=float(np.inf))

    def farthest(k: np.ndarray) -> np.ndarray:
        return cv2.dilate(z_hi, k, borderType=cv2.BORDER_CONSTANT, borderValue=float(-np.inf))

    k = 2 * radius + 1
    box = np.ones((k, k), np.uint8)
    ring = np.ones((3, 3), np.uint8)
    ring[1, 1] = 0  # the 8 direct neighbours, not the pixel itself
    with np.errstate(invalid="ignore"):
        between = (nearest(box) < z - tol) & (farthest(box) > z + tol)
        # spikes: every direct neighbour farther (or every one nearer) by more than the tolerance
        isolated = (nearest(ring) > z + tol) | (farthest(ring) < z - tol)
    # same-surface support among the 8 direct neighbours, only where it decides
    idx = np.flatnonzero(between)
    zp = np.pad(z, 1, mode="constant", constant_values=np.nan).reshape(-1)
    r, c = np.divmod(idx, W)
    centre = (r + 1) * (W + 2) + (c + 1)
    support = np.zeros(len(idx), dtype=np.int16)
    zc, tc = z.reshape(-1)[idx], tol.reshape(-1)[idx]
    for dv in (-1, 0, 1):
        for du in (-1, 0, 1):
            if dv or du:
                with np.errstate(invalid="ignore"):
                    support += np.abs(zp[centre + dv * (W + 2) + du] - zc) <= tc
    flying = isolated & valid
    flying.reshape(-1)[idx[support <= max_support]] = True
    # a pixel between two surfaces with no same-surface neighbour at all is isolated too
    return flying


def denoise_depth(depth_m: np.ndarray, tol_rel: float = 0.01, size: int = 3, min_support: int = 6,
                  exclude: np.ndarray | None = None, block_rows: int = 24) -> np.ndarray:
    """Edge-preserving denoising by same-surface plane fits; see the module docstring.

    ``depth_m`` (H, W) metres (NaN = none); ``exclude`` (H, W) bool pixels that must not enter
    another pixel's fit (flying pixels; their own depth is still refined from the others).
    Returns (H, W) float32, NaN where the input is. Works in blocks of ``block_rows`` rows so
    that the (size^2, rows, W) neighbour stack stays in the CPU cache.
    """
    z = np.asarray(depth_m, dtype=np.float32)
    with np.errstate(invalid="ignore"):
        z = np.where(z > 0, z, np.float32(np.nan))
    H, W = z.shape
    r = size // 2
    src = z if exclude is None else np.where(exclude, np.float32(np.nan), z)
    zp = np.pad(src, r, mode="constant", constant_values=np.nan)
    dv, du = np.mgrid[-r:r + 1, -r:r + 1]
    du, dv = du.ravel(), dv.ravel()
    K = len(du)
    fu, fv = du.astype(np.float32), dv.astype(np.float32)
    A = np.stack([np.ones_like(fu), fu, fv, fu * fu, fv * fv, fu * fv])  # (6, K)
    Bc = A[:3]
    out = np.empty_like(z)
    rows = max(1, int(block_rows))
    d = np.empty((K, rows, W), dtype=np.float32)
    tmp = np.empty((K, rows, W), dtype=np.float32)
    m = np.empty((K, rows, W), dtype=bool)
    for r0 in range(0, H, rows):
        r1 = min(H, r0 + rows)
        h = r1 - r0
        zc = z[r0:r1]
        db, tb, mb = d[:, :h], tmp[:, :h], m[:, :h]
        for k in range(K):
            np.subtract(zp[r0 + r + dv[k]:r1 + r + dv[k], r + du[k]:r + du[k] + W], zc, out=db[k])
        tol = np.float32(tol_rel) * zc
        np.abs(db, out=tb)
        with np.errstate(invalid="ignore"):
            np.less_equal(tb, tol, out=mb)  # NaN compares False
        Mf = mb.reshape(K, -1).astype(np.float32)
        D = db.reshape(K, -1)
        np.copyto(D, 0, where=~mb.reshape(K, -1))
        n, su, sv, suu, svv, suv = A @ Mf  # normal equations of d = a0 + au * du + av * dv
        b0, bu, bv = Bc @ D
        # Cramer's rule for a0 of [[n, su, sv], [su, suu, suv], [sv, suv, svv]] @ a = b (float32 is
        # plenty: integer sums <= 25 * 4, depth differences ~1e-3)
        c0 = suu * svv - suv * suv
        det = n * c0 - su * (su * svv - suv * sv) + sv * (su * suv - suu * sv)
        det0 = b0 * c0 - su * (bu * svv - suv * bv) + sv * (bu * suv - suu * bv)
        with np.errstate(invalid="ignore", divide="ignore"):
            plane = det0 / det
            mean = b0 / n
        # a well-conditioned plane needs spread in both directions (det / n^3 = det of the offsets' covariance, px^4)
        good = (n >= min_support) & (det > np.float32(0.25) * n ** 3)
        corr = np.where(good, plane, np.where(n >= 3, mean, np.float32(0)))
        out[r0:r1] = zc + np.nan_to_num(corr).reshape(h, W)
    return out


def fill_holes(depth_m: np.ndarray, tol_rel: float = 0.01, reach: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Holes (no measurement) between two measured pixels of one surface, filled by linear
    interpolation; see the module docstring.

    ``depth_m`` (H, W) metres, NaN or <= 0 = none. Returns the depth (H, W) float32 (NaN where
    still none) and the mask (H, W) bool of filled pixels.
    """
    z = np.asarray(depth_m, dtype=np.float32)
    with np.errstate(invalid="ignore"):
        z = np.where(z > 0, z, np.float32(np.nan))
    H, W = z.shape
    hole = np.flatnonzero(np.isnan(z))
    filled = np.zeros(z.shape, dtype=bool)
    if len(hole) == 0:
        return z, filled
    r = max(1, int(reach))
    # gathers at the holes only (a few hundred to a few ten thousand pixels), from a padded copy
    Wp = W + 2 * r
    zp = np.pad(z, r, mode="constant", constant_values=np.nan).reshape(-1)
    row, col = np.divmod(hole, W)
    centre = (row + r) * Wp + (col + r)
    acc = np.zeros(len(hole), dtype=np.float32)
    cnt = np.zeros(len(hole), dtype=np.int8)
    for du, dv in ((1, 0), (0, 1), (1, 1), (1, -1)):
        # nearest measured pixel on each side along the line, and how far away it is
        za = np.full(len(hole), np.nan, dtype=np.float32)
        zb = np.full(len(hole), np.nan, dtype=np.float32)
        ia = np.zeros(len(hole), dtype=np.float32)
        ib = np.zeros(len(hole), dtype=np.float32)
        for i in range(r, 0, -1):
            step = i * (dv * Wp + du)
            a, b = zp[centre - step], zp[centre + step]
            fa, fb = ~np.isnan(a), ~np.isnan(b)
            za[fa], ia[fa] = a[fa], i
            zb[fb], ib[fb] = b[fb], i
        s = ia + ib
        with np.errstate(invalid="ignore", divide="ignore"):
            ok = np.abs(za - zb) <= s * np.float32(tol_rel) * np.fmin(za, zb)  # NaN (a side missing): False
            est = (ib * za + ia * zb) / s
        acc[ok] += est[ok]
        cnt[ok] += 1
    got = cnt > 0
    out = z.copy()
    out.reshape(-1)[hole[got]] = acc[got] / cnt[got]
    filled.reshape(-1)[hole[got]] = True
    return out, filled


def snap_flying(depth_m: np.ndarray, flying: np.ndarray) -> np.ndarray:
    """Depth (H, W) float32 with every flying pixel moved onto the surface it shares most of its
    footprint with; NaN where it cannot be decided.

    The mixed depth lies between the nearest and the farthest valid, non-flying 3 x 3 neighbour
    (``z_near``, ``z_far``); a pixel closer to ``z_near`` saw mostly the near surface. It takes
    that neighbour's depth (the plane fit of :func:`denoise_depth` then refines it). Like an
    ideal sensor's pixel centre, which sees whichever surface it falls on, the silhouette then
    sits within half a pixel of the true edge, instead of a pixel inside it when the pixel is
    dropped. Pixels with no valid neighbour on either side become NaN.
    """
    import cv2

    z = np.asarray(depth_m, dtype=np.float32)
    with np.errstate(invalid="ignore"):
        good = (z > 0) & ~flying
    kernel = np.ones((3, 3), np.uint8)
    near = cv2.erode(np.where(good, z, np.float32(np.inf)), kernel, borderType=cv2.BORDER_CONSTANT,
                     borderValue=float(np.inf))
    far = cv2.dilate(np.where(good, z, np.float32(-np.inf)), kernel, borderType=cv2.BORDER_CONSTANT,
                     borderValue=float(-np.inf))
    zf = z[flying]
    nf, ff = near[flying], far[flying]
    with np.errstate(invalid="ignore"):
        snapped = np.where(np.abs(zf - nf) <= np.abs(ff - zf), nf, ff)
    snapped[~np.isfinite(snapped)] = np.nan
    out = z.copy()
    out[flying] = snapped
    return out


def clean_depth(depth_m: np.ndarray, flying: bool = True, jump_rel: float = 0.01, denoise: bool = True,
                denoise_size: int = 3, denoise_tol_rel: float = 0.01,
                repair: bool = True, fill: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Flying-pixel detection, hole filling, then denoising: returns the cleaned depth (H, W)
    float32 metres (NaN where none) and the flying-pixel mask (H, W) bool. Flying pixels are
    moved onto the surface they mostly saw (``repair``, :func:`snap_flying`) or removed; holes
    inside a surface are filled (``fill``, :func:`fill_holes`; the filled pixels are those with
    no measurement in ``depth_m`` and a depth in the result). Neither flying nor filled pixels
    enter another pixel's plane fit."""
    z = np.asarray(depth_m, dtype=np.float32)
    with np.errstate(invalid="ignore"):
        valid = z > 0
    fly = flying_pixels(z, jump_rel) if flying else np.zeros(z.shape, dtype=bool)
    base = np.where(valid, z, np.float32(np.nan))
    if fly.any():
        base = snap_flying(base, fly) if repair else np.where(fly, np.float32(np.nan), base)
    exclude = fly
    if fill:
        got, filled = fill_holes(base, jump_rel)
        if not repair:
            filled &= ~fly  # asked to remove flying pixels: they stay removed
        base = np.where(filled, got, base)
        exclude = fly | filled
    out = denoise_depth(base, denoise_tol_rel, denoise_size, exclude=exclude) if denoise else base
    return out, fly
