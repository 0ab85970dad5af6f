"""Re-click test: fresh crops (random offset, other zoom, no marks) of every landmark, to be read
again by eye; ``compare`` then reports the RMS difference per camera between the eye readings
and the silhouette-feature positions (the curvature extrema before the inward step).

  python reclick.py render OUT_PREFIX      -> OUT_PREFIX_NN.png + OUT_PREFIX.json (crop centres)
  python reclick.py compare READINGS.json  (READINGS: {"<key>#<i>": {"ir": [u, v], "other": [u, v]}})
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import cv2
import numpy as np

from annotate_view import crop_view, hstack
from contour_points import curvature_points, plant_mask

HERE = Path(__file__).resolve().parent
SCALE = {"ir": 1.0, "hyperspectral": 1.8, "thermal": 2.2}


def items():
    ann = json.loads((HERE / "annotations.json").read_text())
    for key in sorted(ann):
        for i, it in enumerate(ann[key]):
            yield f"{key}#{i}", key.split("/")[0], key.split("/")[1], it


def feature(plant: str, cam: str, uv) -> np.ndarray:
    """The silhouette curvature extremum nearest to a landmark (its position before the inward step)."""
    P, K, N = curvature_points(plant_mask(plant, cam), 2.0 * SCALE[cam])
    return P[np.argmin(np.linalg.norm(P - np.asarray(uv), axis=1))]


def render(prefix: str, seed: int = 7, zi: int = 8, hi: int = 12, zo: int = 5, ho: int = 24,
           only: list[str] | None = None) -> None:
    rng = np.random.default_rng(seed)
    rows, meta = [], {}
    for name, plant, cam, it in items():
        if only and name not in only:
            continue
        ci = np.round(np.asarray(it["ir"]) + rng.uniform(-4, 4, 2)).astype(int)
        co = np.round(np.asarray(it["other"]) + rng.uniform(-7, 7, 2)).astype(int)
        a = crop_view(plant, "ir", *ci, hi, zi, [], title=name, tick=5)
        b = crop_view(plant, cam, *co, ho, zo, [], title=name, tick=5, stretch_hs=True)
        rows.append(hstack([a, b]))
        meta[name] = {"ir_centre": ci.tolist(), "other_centre": co.tolist()}
    w = max(r.shape[1] for r in rows)
    rows = [np.pad(r, ((0, 6), (0, w - r.shape[1] + 10), (0, 0)), constant_values=255) for r in rows]
    while len(rows) % 3:
        rows.append(np.full_like(rows[0], 255))
    for k in range(0, len(rows), 6):
        rr = rows[k:k + 6]
        cv2.imwrite(f"{prefix}_{k // 6:02d}.png", np.concatenate([np.concatenate(rr[j:j + 3], 1) for j in range(0, len(rr), 3)], 0))
    Path(prefix + ".json").write_text(json.dumps(meta, indent=1))


def compare(path: str) -> None:
    rd = json.loads(Path(path).read_text())
    diffs: dict[str, list[float]] = {}
    for name, plant, cam, it in items():
        if name not in rd:
            continue
        for c, key in (("ir", "ir"), (cam, "other")):
            f = feature(plant, c, it[key])
            dd = float(np.linalg.norm(np.asarray(rd[name][key]) - f))
            diffs.setdefault(c, []).append(dd)
            print(f"{name:34s} {c:13s} eye {rd[name][key]} feature {np.round(f, 1).tolist()} diff {dd:.2f}")
    for c, v in diffs.items():
        v = np.asarray(v)
        print(f"{c}: n={len(v)} rms {np.sqrt(np.mean(v ** 2)):.2f} px, median {np.median(v):.2f}, max {v.max():.2f}")


if __name__ == "__main__":
    if sys.argv[1] == "render":  # render PREFIX [SEED ZI HI ZO HO [READINGS.json: only these]]
        extra = [int(x) for x in sys.argv[3:8]]
        only = list(json.loads(Path(sys.argv[8]).read_text())) if len(sys.argv) > 8 else None
        render(sys.argv[2], *extra, only=only)
    else:
        compare(sys.argv[2])
