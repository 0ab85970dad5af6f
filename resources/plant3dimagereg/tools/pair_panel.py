"""Batch pair panels for annotation: rows of (infrared crop | other-camera crop) with grids.

Input: a JSON list of {"id", "plant", "ir": [u, v], "cam": "thermal"|"hyperspectral", "other": [u, v]}
(``other`` is only where to centre the crop — a rough guess, e.g. from a coarse silhouette alignment;
it is NEVER taken as the landmark: the landmark is read by eye from the grid in both crops).
Each crop is marked with a yellow cross at the given position, so a reading can also be checked
by passing the read coordinates back in.

  python resources/plant3dimagereg/tools/pair_panel.py items.json out_prefix [--per 4] [--zoom-ir 8]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import cv2
import numpy as np

from annotate_view import crop_view, hstack


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("items", type=Path)
    ap.add_argument("out")
    ap.add_argument("--per", type=int, default=4)
    ap.add_argument("--half-ir", type=int, default=10)
    ap.add_argument("--zoom-ir", type=int, default=9)
    ap.add_argument("--half-other", type=int, default=20)
    ap.add_argument("--zoom-other", type=int, default=5)
    a = ap.parse_args()
    items = json.loads(a.items.read_text())
    for k in range(0, len(items), a.per):
        rows = []
        for it in items[k:k + a.per]:
            v1 = crop_view(it["plant"], "ir", *it["ir"], a.half_ir, a.zoom_ir, [tuple(it["ir"])], title=f"#{it['id']}")
            v2 = crop_view(it["plant"], it["cam"], *it["other"], a.half_other, a.zoom_other, [tuple(it["other"])],
                           title=f"#{it['id']}")
            rows.append(hstack([v1, v2]))
        w = max(r.shape[1] for r in rows)
        rows = [np.pad(r, ((0, 6), (0, w - r.shape[1]), (0, 0)), constant_values=255) for r in rows]
        # two pairs side by side per row of the panel
        lines = []
        for j in range(0, len(rows), 2):
            pair = rows[j:j + 2]
            if len(pair) == 1:
                pair.append(np.full_like(pair[0], 255))
            lines.append(np.concatenate(pair, axis=1))
        cv2.imwrite(f"{a.out}_{k // a.per:02d}.png", np.concatenate(lines, axis=0))


if __name__ == "__main__":
    main()
