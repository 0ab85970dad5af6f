"""Landmarks from two independent eye readings: ``annotations.json`` from ``eye_readings.json``.

``eye_readings.json``: {"PLANT/CAMERA#i": {"note": ..., "r1": {"ir": [u, v], "other": [u, v]},
"r2": {...}}} — two readings of the same silhouette feature (leaf tip, notch, corner, sinus) on
fresh crops (different offsets and zoom, no marks; ``reclick.py``). A point is kept when the
readings agree (<= 2 px infrared, <= 4 px in the other camera); the landmark is their mean, then
moved inward onto the leaf (from 0 px) until the infrared pixel is valid, within 25 mm of the leaf 4 px further in, and its 3x3 neighbourhood (>= 7 valid) has
consistent depth (a silhouette point itself is a flying pixel or a hole; up to 10 px), and the other camera's
point is moved inward by the same physical distance (x 1.8 hyperspectral, x 2.2 thermal pixels per
infrared pixel near the plants) along its own silhouette's inward normal. A reading's
``"held_out"`` entry (why it is kept out of rig.json's fit) and ``"held_out_kind"`` (``independent``:
read without any mark of a rig's prediction; ``found_with_rig``: located with rig.json's predictions)
are carried over (build_landmarks.py writes those points to ``landmarks_heldout.json``), and so is
``"session"`` (how a later session read it).

Session 11 (issue 23): the readings of ``eye_readings_s11*.json`` (one file per reader, same format;
a reading with ``"dropped"`` is the reader's own verdict that it is no landmark and is skipped)
are read too (a name in two files is refused). Their inward step goes towards the front surface
(``front_normal``: a near leaf's margin seen over a leaf below belongs to the near leaf; the plant
mask holds both), the other camera's along the infrared step turned as the camera is, and their
infrared point must also pass plantreg's own
depth check after the step (``rigfit.check_landmark_depth``: not a depth jump to the ground or
another surface) or the pair is dropped. Of the kept session-11 thermal pairs, a fixed seeded
third is held out as ``"independent"`` (``held_out_s11``: the rule was fixed before any fit).
The x 2.2 is a guess:
the rig's local scale is 1.81-2.16 (1.85 near the image centre; ``step_variants.py scales``);
the alternatives measured in session landmarks (README) were not better by the held-out measures.

  python resources/plant3dimagereg/landmark_scripts/finalize.py [--thermal-scale X --out FILE]

``--thermal-scale X``: the thermal step as X thermal px per infrared px instead of 2.2 (session 11
measured 1.98 from the pairs themselves, ``pair_scale.py``), written to FILE instead of
annotations.json (``ANNOTATIONS=FILE refit_eval.py ...`` measures it).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from annotate_view import load
from contour_points import plant_mask

HERE = Path(__file__).resolve().parent
SCALE = {"hyperspectral": 1.8, "thermal": 2.2}
AGREE = {"ir": 2.0, "other": 4.0}
S11_SEED = 2311  # session 11's held-out draw (fixed before any fit; README "Session 11")
GROUND_Z = 1.15  # rig_nominal.json's ROI far limit: the tray's floor lies beyond it


#: the session-11 readers whose pairs may be fitted; ``eye_readings_s11c.json`` is the independent
#: evaluation reader's (``../landmarks_independent_s11.json``, never fitted; another format)
S11_FILES = ("eye_readings_s11a.json", "eye_readings_s11b.json")


def readings() -> tuple[dict, set[str]]:
    """All eye readings (``eye_readings.json`` + ``eye_readings_s11*.json``) and the names read in
    session 11. A name in two files is refused (two readers' pairs must stay apart)."""
    rd = json.loads((HERE / "eye_readings.json").read_text())
    s11: set[str] = set()
    for f in [HERE / n for n in S11_FILES]:
        for name, r in json.loads(f.read_text()).items():
            if name in rd:
                raise SystemExit(f"{f.name}: {name} is already read in another file")
            rd[name] = r
            s11.add(name)
    return rd, s11


def held_out_s11(kept: list[str], seed: int = S11_SEED) -> set[str]:
    """Session-11 thermal names held out: ceil(n / 3) of all n kept session-11 thermal pairs (pooled
    over the plants: the readers found 0-2 per plant, and a third per plant would hold out every
    pair of a plant with one), the first of a permutation of the sorted names by a numpy generator
    seeded with ``seed``. Fixed before any fit with the new pairs (README "Session 11")."""
    g = sorted(n for n in kept if n.split("#")[0].endswith("/thermal"))
    return {g[i] for i in np.random.default_rng(seed).permutation(len(g))[:-(-len(g) // 3)]}


def inward_normal(plant: str, cam: str, uv: np.ndarray, radius: float) -> np.ndarray:
    """Unit vector from a silhouette point towards the centroid of the plant-mask pixels within
    ``radius`` (along the leaf axis at a tip, into the leaf at a notch or an edge)."""
    m = plant_mask(plant, cam)
    v, u = np.nonzero(m[max(int(uv[1] - radius), 0):int(uv[1] + radius) + 1,
                        max(int(uv[0] - radius), 0):int(uv[0] + radius) + 1])
    u = u + max(int(uv[0] - radius), 0)
    v = v + max(int(uv[1] - radius), 0)
    keep = (u - uv[0]) ** 2 + (v - uv[1]) ** 2 <= radius ** 2
    if not keep.any() and cam == "ir":
        # a leaf tip in front of the tray's frame: the plant mask drops the frame's pixels and the
        # tip with them; use the front surface instead (valid depth within 50 mm of the nearest)
        d = load(plant, "depth").astype(np.float64)
        r0, c0 = max(int(uv[1] - radius), 0), max(int(uv[0] - radius), 0)
        win = d[r0:int(uv[1] + radius) + 1, c0:int(uv[0] + radius) + 1]
        v, u = np.nonzero((win > 0) & (win < win[win > 0].min() + 50))
        u, v = u + c0, v + r0
        keep = (u - uv[0]) ** 2 + (v - uv[1]) ** 2 <= radius ** 2
    c = np.array([u[keep].mean(), v[keep].mean()]) - uv
    return c / max(np.linalg.norm(c), 1e-9)


def find_step(d: np.ndarray, pi: np.ndarray, ni: np.ndarray) -> float | None:
    """Smallest step (0-10 px, 0.5 px apart) along ``ni`` from ``pi`` onto valid leaf depth: on the
    plant (< 1.13 m, not the tray), a consistent 3x3 neighbourhood, within 25 mm of the leaf 4 px further in."""
    for s in np.arange(0.0, 10.01, 0.5):
        u, v = np.round(pi + ni * s).astype(int)
        blk = d[v - 1:v + 2, u - 1:u + 2].astype(float)
        ok = blk[blk > 0]
        u2, v2 = np.round(pi + ni * (s + 4)).astype(int)  # the same leaf 4 px further in
        inner = d[v2 - 1:v2 + 2, u2 - 1:u2 + 2].astype(float)
        inner = inner[inner > 0]
        if (blk.shape == (3, 3) and 0 < blk[1, 1] < 1130 and ok.size >= 7  # on the plant, not the tray
                and np.max(np.abs(ok - np.median(ok))) < 15 and abs(blk[1, 1] - np.median(ok)) < 8
                and inner.size and abs(blk[1, 1] - np.median(inner)) < 25):
            return float(s)
    return None


def front_normal(d: np.ndarray, uv: np.ndarray, radius: float) -> np.ndarray:
    """Unit vector from ``uv`` towards the centroid of the front surface's pixels within ``radius``
    (valid depth within 25 mm of the window's 5th-percentile depth): into the near leaf at its margin."""
    r0, c0 = max(int(uv[1] - radius), 0), max(int(uv[0] - radius), 0)
    win = d[r0:int(uv[1] + radius) + 1, c0:int(uv[0] + radius) + 1].astype(float)
    near = np.percentile(win[win > 0], 5)
    v, u = np.nonzero((win > 0) & (win < near + 25))
    u, v = u + c0, v + r0
    keep = (u - uv[0]) ** 2 + (v - uv[1]) ** 2 <= radius ** 2
    c = np.array([u[keep].mean(), v[keep].mean()]) - uv
    return c / max(np.linalg.norm(c), 1e-9)


def main(out_path: Path | None = None) -> None:
    import sys

    sys.path.insert(0, str(HERE.parents[2]))  # the project root (plantreg_gui)
    from plantreg_gui.core.rigfit.rigfit import check_landmark_depth

    rd, s11 = readings()
    out: dict[str, list] = {}
    names: dict[int, str] = {}
    dropped = []
    depth_cache: dict[str, np.ndarray] = {}
    for name, r in rd.items():
        key, _ = name.split("#")
        plant, cam = key.split("/")
        if r.get("dropped"):  # the reader's own verdict (a session-11 reading kept as read, not a landmark)
            dropped.append((name, "reader: " + str(r["dropped"])[:60]))
            continue
        a1, a2 = np.asarray(r["r1"]["ir"], float), np.asarray(r["r2"]["ir"], float)
        b1, b2 = np.asarray(r["r1"]["other"], float), np.asarray(r["r2"]["other"], float)
        if np.linalg.norm(a1 - a2) > AGREE["ir"] or np.linalg.norm(b1 - b2) > AGREE["other"]:
            dropped.append((name, round(float(np.linalg.norm(a1 - a2)), 1), round(float(np.linalg.norm(b1 - b2)), 1)))
            continue
        pi, po = (a1 + a2) / 2, (b1 + b2) / 2
        d = depth_cache.setdefault(plant, load(plant, "depth"))
        ni = inward_normal(plant, "ir", pi, 8.0)
        no = inward_normal(plant, cam, po, 8.0 * SCALE[cam])
        how_in = "plant mask"
        if name in s11:
            # session 11: a silhouette point belongs to the front surface, also where a near leaf's
            # margin is seen over a leaf below (both are plant: the plant mask's centroid can lie on
            # the leaf behind, and the step would land there); the other camera's direction is the
            # infrared one turned as the camera is (thermal x = -infrared y, thermal y = infrared x;
            # hyperspectral the other way), not its own silhouette's
            ni, how_in = front_normal(d, pi, 8.0), "front surface"
            no = np.array([-ni[1], ni[0]]) if cam == "thermal" else np.array([ni[1], -ni[0]])
        step = find_step(d, pi, ni)
        if step is None:
            dropped.append((name, "no valid depth within 10 px"))
            continue
        if name in s11:
            chk = check_landmark_depth(d / 1000.0, pi + ni * step, GROUND_Z, snap=False)
            if chk.status != "ok":
                dropped.append((name, f"depth check: {chk.status}"))
                continue
        out.setdefault(key, []).append({
            "ir": np.round(pi + ni * step, 2).tolist(), "other": np.round(po + no * step * SCALE[cam], 2).tolist(),
            "note": r["note"], "feature_ir": pi.round(2).tolist(), "feature_other": po.round(2).tolist(),
            "inward_step_ir_px": step, **({"inward_direction": how_in} if name in s11 else {}), **{k: r[k] for k in ("held_out", "held_out_kind", "session") if k in r},
            "how": "mean of two eye readings of the silhouette feature (reclick.py crops), moved inward onto valid depth"})
        names[id(out[key][-1])] = name
    held = held_out_s11([n for n in names.values() if n in s11])
    for key, items in out.items():
        for it in items:
            if names[id(it)] in held:
                it["held_out"] = ("session 11: a fixed seeded third of the new thermal pairs (finalize.held_out_s11, "
                                  f"seed {S11_SEED}), chosen before any fit; read without any rig's prediction")
                it["held_out_kind"] = "independent"
    (out_path or HERE / "annotations.json").write_text(json.dumps(out, indent=1) + "\n")
    print({k: len(v) for k, v in out.items()}, "dropped:", dropped)




def agreement() -> None:
    """RMS difference between the two readings, per camera (all read points, and the kept ones)."""
    rd, _ = readings()
    for subset in ("all", "kept"):
        diffs: dict[str, list[float]] = {}
        for name, r in rd.items():
            cam = name.split("#")[0].split("/")[1]
            di = float(np.linalg.norm(np.subtract(r["r1"]["ir"], r["r2"]["ir"])))
            do = float(np.linalg.norm(np.subtract(r["r1"]["other"], r["r2"]["other"])))
            if subset == "kept" and (di > AGREE["ir"] or do > AGREE["other"] or r.get("dropped")):
                continue
            diffs.setdefault("ir", []).append(di)
            diffs.setdefault(cam, []).append(do)
        for c, v in diffs.items():
            v = np.asarray(v)
            print(f"{subset:4s} {c:13s} n={len(v):2d} rms {np.sqrt(np.mean(v ** 2)):.2f} px  median {np.median(v):.2f}  max {v.max():.2f}")


if __name__ == "__main__":
    import sys

    if sys.argv[1:] == ["--agreement"]:
        agreement()
    elif "--thermal-scale" in sys.argv:
        SCALE["thermal"] = float(sys.argv[sys.argv.index("--thermal-scale") + 1])
        main(Path(sys.argv[sys.argv.index("--out") + 1]))
    else:
        main()
