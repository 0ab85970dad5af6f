"""Render zoomed, contrast-stretched crops with a pixel grid for reading landmark coordinates by eye.

Used to annotate ``../landmarks.json``. Pixel convention: pixel centres at integer coordinates
(u = column, v = row); in a crop zoomed by Z the pixel (u, v) is the Z x Z block whose centre is
drawn at ((u - u0 + 0.5) * Z, (v - v0 + 0.5) * Z). Grid lines are pixel *borders* (u +- 0.5); tick
labels name the pixel centre of every 5th column/row (tick marks at the centre).

Stretches (per crop, so that dim leaves and hot pots both show):
  ir            log(1 + value), 1-99.5 percentile of the crop
  depth         1-99 percentile of valid depth in the crop, 0 shown red
  thermal       2-98 percentile of the crop (degrees C, the float .npy, not the display PNG)
  hyperspectral the RGB render as it is (optionally per-channel 1-99 percentile stretch)

Examples (from the project root)::

  python resources/plant3dimagereg/landmark_scripts/annotate_view.py overview 01grapevine /tmp/ov
  python resources/plant3dimagereg/landmark_scripts/annotate_view.py crop 01grapevine ir 300 250 --half 20 --zoom 10 \
      --mark 301.5,249.0 -o /tmp/c.png
  python resources/plant3dimagereg/landmark_scripts/annotate_view.py pair 01grapevine ir 300 250 hyperspectral 250 300 -o /tmp/p.png
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

DATA = Path(__file__).resolve().parents[4] / "shared" / "data" / "plant3dimagereg"
if not DATA.is_dir():  # worktree layout /work/<tree>/resources/plant3dimagereg/landmark_scripts
    DATA = Path("/work/shared/data/plant3dimagereg")


def load(plant: str, cam: str) -> np.ndarray:
    if cam == "ir":
        return np.load(DATA / "infra_np" / f"{plant}.npy").astype(np.float64)
    if cam == "irhp":  # infrared high-pass (veins): log(IR) minus its Gaussian blur (sigma 3 px)
        a = np.log1p(np.load(DATA / "infra_np" / f"{plant}.npy").astype(np.float64))
        return a - cv2.GaussianBlur(a, (0, 0), 3.0)
    if cam == "depth":
        return np.load(DATA / "lidar_depthmap_np" / f"{plant}.npy").astype(np.float64)
    if cam == "thermal":
        return np.load(DATA / "thermal_np_01" / f"{plant}.npy").astype(np.float64)
    if cam in ("hyperspectral", "hs"):
        return cv2.imread(str(DATA / "hs" / f"{plant}.png"), cv2.IMREAD_COLOR)  # BGR uint8
    if cam == "pca":
        return cv2.imread(str(DATA / "hs_pca_01" / f"{plant}.png"), cv2.IMREAD_COLOR)
    raise SystemExit(f"unknown camera {cam}")


def stretch(cam: str, a: np.ndarray, stretch_hs: bool = False) -> np.ndarray:
    """Crop -> BGR uint8 with the per-crop stretch of the module docstring."""
    if a.ndim == 3:
        if not stretch_hs:
            return a.copy()
        out = np.empty_like(a)
        for c in range(3):
            lo, hi = np.percentile(a[..., c], [1, 99])
            out[..., c] = np.clip((a[..., c] - lo) / max(hi - lo, 1) * 255, 0, 255)
        return out
    a = a.astype(np.float64)
    valid = np.isfinite(a)
    if cam == "ir":
        a = np.log1p(np.maximum(a, 0))
        lo, hi = np.percentile(a, [1, 99.5])
    elif cam == "depth":
        valid = a > 0
        lo, hi = np.percentile(a[valid], [1, 99]) if valid.any() else (0, 1)
    else:
        lo, hi = np.percentile(a[valid], [2, 98])
    g = np.clip((a - lo) / max(hi - lo, 1e-9) * 255, 0, 255).astype(np.uint8)
    if cam in ("ir", "thermal") and min(g.shape) >= 32:
        # local contrast (veins on bright leaves, blurred thermal borders); CLAHE keeps pixel positions
        g = cv2.createCLAHE(clipLimit=3.0, tileGridSize=(max(g.shape[0] // 40, 1), max(g.shape[1] // 40, 1))).apply(g)
    out = cv2.cvtColor(g, cv2.COLOR_GRAY2BGR)
    if cam == "depth":
        out[~valid] = (0, 0, 200)
    return out


ROT_TO_IR = {"ir": 0, "irhp": 0, "depth": 0, "thermal": 1, "hyperspectral": -1, "hs": -1, "pca": -1}
"""np.rot90 k that turns a camera's crop into the infrared's orientation (display only; the
thermal is seen ~90 deg clockwise of the infrared, the hyperspectral ~90 deg anticlockwise)."""


def crop_view(plant: str, cam: str, u: float, v: float, half: int = 20, zoom: int = 10,
              marks: list[tuple[float, float]] = (), stretch_hs: bool = False, title: str = "",
              rot: int | None = None, tick: int = 5) -> np.ndarray:
    """Zoomed crop around (u, v) with a grid of pixel borders. With ``rot`` (np.rot90 k; default: to
    the infrared's orientation) the crop is turned for display, and the axis labels name the
    ORIGINAL coordinate that is constant along each displayed column/row ("u=..", "v=..")."""
    img = load(plant, cam)
    rot = ROT_TO_IR.get(cam, 0) if rot is None else rot
    H, W = img.shape[:2]
    u0, v0 = int(round(u)) - half, int(round(v)) - half
    n = 2 * half + 1
    pad = np.zeros((n, n) + img.shape[2:], img.dtype)
    su0, sv0, su1, sv1 = max(u0, 0), max(v0, 0), min(u0 + n, W), min(v0 + n, H)
    if su1 > su0 and sv1 > sv0:
        pad[sv0 - v0:sv1 - v0, su0 - u0:su1 - u0] = img[sv0:sv1, su0:su1]
    rgb = stretch(cam, pad, stretch_hs)
    V, U = np.mgrid[v0:v0 + n, u0:u0 + n]
    rgb, U, V = np.rot90(rgb, rot), np.rot90(U, rot), np.rot90(V, rot)
    rgb = np.ascontiguousarray(rgb)
    big = cv2.resize(rgb, None, fx=zoom, fy=zoom, interpolation=cv2.INTER_NEAREST)
    for i in range(n + 1 if zoom >= 7 else 0):  # pixel borders (only where there is room)
        cv2.line(big, (i * zoom, 0), (i * zoom, n * zoom), (70, 70, 70), 1)
        cv2.line(big, (0, i * zoom), (n * zoom, i * zoom), (70, 70, 70), 1)
    if zoom < 7:  # coarse views: faint lines every ``tick`` pixels instead
        for i in range(n):
            if (U[0, i] if np.all(U[:, 0] == U[0, 0]) else V[0, i]) % tick == 0:
                cv2.line(big, (int((i + 0.5) * zoom), 0), (int((i + 0.5) * zoom), n * zoom), (0, 140, 0), 1)
            if (V[i, 0] if np.all(U[:, 0] == U[0, 0]) else U[i, 0]) % tick == 0:
                cv2.line(big, (0, int((i + 0.5) * zoom)), (n * zoom, int((i + 0.5) * zoom)), (0, 140, 0), 1)
    M = 56  # margin for labels
    canvas = np.full((n * zoom + M + 22, n * zoom + M, 3), 255, np.uint8)
    canvas[M:M + n * zoom, M:M + n * zoom] = big
    col_is_u = np.all(U[:, 0] == U[0, 0])  # along a displayed column, u is constant
    cols = U[0, :] if col_is_u else V[0, :]
    rows = V[:, 0] if col_is_u else U[:, 0]
    cname, rname = ("u", "v") if col_is_u else ("v", "u")
    for i in range(n):
        x = M + int((i + 0.5) * zoom)
        if cols[i] % tick == 0:
            cv2.line(canvas, (x, M - 6), (x, M), (0, 0, 0), 1)
            cv2.putText(canvas, str(cols[i]), (x - 12, M - 10 - 12 * ((cols[i] // tick) % 2)),
                        cv2.FONT_HERSHEY_PLAIN, 0.8, (0, 0, 0), 1)
        if rows[i] % tick == 0:
            cv2.line(canvas, (M - 6, x), (M, x), (0, 0, 0), 1)
            cv2.putText(canvas, str(rows[i]), (2, x + 4), cv2.FONT_HERSHEY_PLAIN, 0.8, (0, 0, 0), 1)
    cv2.putText(canvas, f"cols:{cname} rows:{rname}", (2, 12), cv2.FONT_HERSHEY_PLAIN, 0.8, (200, 0, 0), 1)

    def disp(mu: float, mv: float) -> tuple[float, float]:
        a = np.zeros((n, n)); a[0, 0] = 1  # where does original (0,0) of the crop go, and the axes?
        fu = (mu - u0) ; fv = (mv - v0)
        # map fractional crop coords through the same rot90: use the corners of the index grids
        cu = (fu - (U[0, 0] - u0)) / ((U[0, -1] - U[0, 0]) or 1) if col_is_u else None
        if col_is_u:
            x = (mu - U[0, 0]) / (U[0, -1] - U[0, 0]) * (n - 1)
            y = (mv - V[0, 0]) / (V[-1, 0] - V[0, 0]) * (n - 1)
        else:
            x = (mv - V[0, 0]) / (V[0, -1] - V[0, 0]) * (n - 1)
            y = (mu - U[0, 0]) / (U[-1, 0] - U[0, 0]) * (n - 1)
        return x, y

    for k, (mu, mv) in enumerate(marks):
        x, y = disp(mu, mv)
        c = (0, 255, 255) if k == 0 else (255, 0, 255)
        cv2.drawMarker(canvas, (int(round(M + (x + 0.5) * zoom)), int(round(M + (y + 0.5) * zoom))), c,
                       cv2.MARKER_CROSS, max(zoom * 2, 12), 1)
    cv2.putText(canvas, f"{plant} {cam} ({u:.1f},{v:.1f}) {title}", (2, canvas.shape[0] - 6),
                cv2.FONT_HERSHEY_PLAIN, 0.9, (0, 0, 160), 1)
    return canvas


def hstack(views: list[np.ndarray]) -> np.ndarray:
    h = max(v.shape[0] for v in views)
    views = [np.pad(v, ((0, h - v.shape[0]), (0, 8), (0, 0)), constant_values=255) for v in views]
    return np.concatenate(views, axis=1)


def overview(plant: str, out: Path, step: int = 50) -> None:
    """Whole images at 2x with a labelled 50-pixel grid, one PNG per camera (+ depth)."""
    out.mkdir(parents=True, exist_ok=True)
    for cam in ("ir", "depth", "thermal", "hyperspectral"):
        img = load(plant, cam)
        rgb = stretch(cam, img)
        z = 2
        big = cv2.resize(rgb, None, fx=z, fy=z, interpolation=cv2.INTER_NEAREST)
        for x in range(0, img.shape[1], step):
            cv2.line(big, (int((x + 0.5) * z), 0), (int((x + 0.5) * z), big.shape[0]), (0, 200, 0), 1)
            cv2.putText(big, str(x), (int((x + 0.5) * z) + 2, 12), cv2.FONT_HERSHEY_PLAIN, 0.9, (0, 255, 0), 1)
        for y in range(0, img.shape[0], step):
            cv2.line(big, (0, int((y + 0.5) * z)), (big.shape[1], int((y + 0.5) * z)), (0, 200, 0), 1)
            cv2.putText(big, str(y), (2, int((y + 0.5) * z) - 2), cv2.FONT_HERSHEY_PLAIN, 0.9, (0, 255, 0), 1)
        cv2.imwrite(str(out / f"{plant}_{cam}.png"), big)


def region(plant: str, cam: str, u0: int, v0: int, u1: int, v1: int, zoom: int = 3, step: int = 10,
           stretch_hs: bool = False) -> np.ndarray:
    """A region [u0, u1) x [v0, v1) at ``zoom`` with a labelled grid every ``step`` pixels (at centres)."""
    img = load(plant, cam)
    sub = img[max(v0, 0):v1, max(u0, 0):u1]
    u0, v0 = max(u0, 0), max(v0, 0)
    rgb = stretch(cam, sub, stretch_hs)
    big = cv2.resize(rgb, None, fx=zoom, fy=zoom, interpolation=cv2.INTER_NEAREST)
    for x in range((u0 // step + 1) * step, u0 + sub.shape[1], step):
        X = int((x - u0 + 0.5) * zoom)
        cv2.line(big, (X, 0), (X, big.shape[0]), (0, 160, 0) if x % 50 else (0, 255, 255), 1)
        if x % 20 == 0:
            cv2.putText(big, str(x), (X + 2, 11), cv2.FONT_HERSHEY_PLAIN, 0.8, (0, 255, 0), 1)
    for y in range((v0 // step + 1) * step, v0 + sub.shape[0], step):
        Y = int((y - v0 + 0.5) * zoom)
        cv2.line(big, (0, Y), (big.shape[1], Y), (0, 160, 0) if y % 50 else (0, 255, 255), 1)
        if y % 20 == 0:
            cv2.putText(big, str(y), (2, Y - 2), cv2.FONT_HERSHEY_PLAIN, 0.8, (0, 255, 0), 1)
    return big


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    o = sub.add_parser("overview")
    o.add_argument("plant")
    o.add_argument("out", type=Path)
    c = sub.add_parser("crop")
    c.add_argument("plant")
    c.add_argument("cam")
    c.add_argument("u", type=float)
    c.add_argument("v", type=float)
    c.add_argument("--half", type=int, default=20)
    c.add_argument("--zoom", type=int, default=10)
    c.add_argument("--mark", action="append", default=[])
    c.add_argument("--stretch-hs", action="store_true")
    c.add_argument("-o", type=Path, required=True)
    p = sub.add_parser("pair")
    p.add_argument("plant")
    p.add_argument("cam1")
    p.add_argument("u1", type=float)
    p.add_argument("v1", type=float)
    p.add_argument("cam2")
    p.add_argument("u2", type=float)
    p.add_argument("v2", type=float)
    p.add_argument("--half", type=int, default=20)
    p.add_argument("--zoom", type=int, default=8)
    p.add_argument("--half2", type=int, default=None)
    p.add_argument("--zoom2", type=int, default=None)
    p.add_argument("--stretch-hs", action="store_true")
    p.add_argument("-o", type=Path, required=True)
    r = sub.add_parser("region")
    r.add_argument("plant")
    r.add_argument("cam")
    r.add_argument("box", type=int, nargs=4, metavar=("U0", "V0", "U1", "V1"))
    r.add_argument("--zoom", type=int, default=3)
    r.add_argument("--step", type=int, default=10)
    r.add_argument("--stretch-hs", action="store_true")
    r.add_argument("-o", type=Path, required=True)
    a = ap.parse_args()
    if a.cmd == "overview":
        overview(a.plant, a.out)
    elif a.cmd == "region":
        cv2.imwrite(str(a.o), region(a.plant, a.cam, *a.box, a.zoom, a.step, a.stretch_hs))
    elif a.cmd == "crop":
        marks = [tuple(float(x) for x in m.split(",")) for m in a.mark]
        cv2.imwrite(str(a.o), crop_view(a.plant, a.cam, a.u, a.v, a.half, a.zoom, marks, a.stretch_hs))
    else:
        v1 = crop_view(a.plant, a.cam1, a.u1, a.v1, a.half, a.zoom, [(a.u1, a.v1)])
        v2 = crop_view(a.plant, a.cam2, a.u2, a.v2, a.half2 or a.half, a.zoom2 or a.zoom, [(a.u2, a.v2)],
                       a.stretch_hs)
        cv2.imwrite(str(a.o), hstack([v1, v2]))


if __name__ == "__main__":
    main()
