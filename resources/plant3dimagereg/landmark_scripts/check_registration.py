"""Side-by-side check of a registration into the infrared: for each source camera, the infrared,
the registered source and an overlay (infrared in grey, the source's edges in magenta, the
infrared's edges in green) over a plant crop, 2x. Judge whether leaf edges line up.

  python check_registration.py OUT_DIR PLANT PANEL.png [U0 V0 U1 V1]
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np
import tifffile

from annotate_view import load, stretch


def norm8(a: np.ndarray, lo: float = 1, hi: float = 99) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    f = np.isfinite(a)
    if not f.any():
        return np.zeros(a.shape, np.uint8)
    p0, p1 = np.percentile(a[f], [lo, hi])
    out = np.clip((a - p0) / max(p1 - p0, 1e-9) * 255, 0, 255)
    out[~f] = 0
    return out.astype(np.uint8)


def main() -> None:
    out, plant, panel = Path(sys.argv[1]), sys.argv[2], sys.argv[3]
    u0, v0, u1, v1 = (int(x) for x in sys.argv[4:8]) if len(sys.argv) > 7 else (170, 110, 430, 350)
    ir = stretch("ir", load(plant, "ir")[v0:v1, u0:u1])[..., 0]  # log + CLAHE, as for annotation
    e_ir = cv2.Canny(cv2.GaussianBlur(ir, (3, 3), 0), 40, 100)
    rows = []
    for cam in ("hyperspectral", "thermal"):
        f = out / "registered" / f"{cam}.tif"
        if not f.is_file():
            continue
        a = tifffile.imread(f)
        g = a.mean(axis=2) if a.ndim == 3 else a
        g8 = norm8(g[v0:v1, u0:u1], 2, 98)
        e = cv2.Canny(cv2.GaussianBlur(g8, (3, 3), 0), 40, 100)
        ov = cv2.cvtColor(ir // 2 + 64, cv2.COLOR_GRAY2BGR)
        ov[e_ir > 0] = (0, 200, 0)
        ov[e > 0] = (255, 0, 255)
        ov[(e > 0) & (e_ir > 0)] = (255, 255, 255)
        src = cv2.cvtColor(g8, cv2.COLOR_GRAY2BGR) if a.ndim == 2 else cv2.cvtColor(norm8(a[v0:v1, u0:u1]), cv2.COLOR_RGB2BGR)
        row = np.concatenate([cv2.cvtColor(ir, cv2.COLOR_GRAY2BGR), src, ov], axis=1)
        row = cv2.resize(row, None, fx=2, fy=2, interpolation=cv2.INTER_NEAREST)
        cv2.putText(row, f"{plant}: ir | {cam} registered | overlay (green ir edges, magenta {cam} edges)",
                    (6, 18), cv2.FONT_HERSHEY_PLAIN, 1.2, (0, 255, 255), 1)
        rows.append(row)
    cv2.imwrite(panel, np.concatenate(rows, axis=0))


if __name__ == "__main__":
    main()
