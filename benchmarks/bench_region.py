"""Time core.region.region_stats on a 4K target (3840x2160): a thermal-like single band (dense)
and a 204-band cube stored as a HitImage, over a 600x500 rectangle and the whole image.

    python benchmarks/bench_region.py
"""

import time
from types import SimpleNamespace

import numpy as np

from plantreg_gui.core.registration.hits import HitImage
from plantreg_gui.core.registration.region import region_mask, region_stats


def main() -> None:
    H, W, B = 2160, 3840, 204
    rng = np.random.default_rng(0)
    obj = np.zeros((H, W), bool)
    obj[500:1700, 1000:2800] = True
    idx = np.flatnonzero(obj.ravel())
    hs = HitImage(idx, rng.random((idx.size, B), dtype=np.float32), (H, W, B))
    th = np.where(obj, 20 + rng.random((H, W), dtype=np.float32), np.nan).astype(np.float32)
    cases = np.where(obj, 1, 0).astype(np.uint8)
    r = SimpleNamespace(shape=(H, W), registered={"hs": hs, "thermal": th}, cases={"hs": cases, "thermal": cases},
                        mixed={}, points_rig=np.full((H, W, 3), np.nan, np.float32))
    for rect in [(900, 400, 1500, 900), (0, 0, W, H)]:
        m = region_mask((H, W), rect=rect)
        for src in ("thermal", "hs"):
            t = time.perf_counter()
            st = region_stats(r, m, src)
            print(f"rect {rect} {src}: {st.trusted:,} P1 px x {st.bands} bands: {time.perf_counter() - t:.2f} s")


if __name__ == "__main__":
    main()
