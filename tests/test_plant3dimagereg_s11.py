"""Session 11's infrared-thermal pairs (resources/plant3dimagereg, README "Session 11"): read without
any rig by two readers, kept by finalize.py's rules, and its step onto the front surface.

Ground truth: the two eye readings of each pair (``landmark_scripts/eye_readings_s11*.json``) and the
depth map under them; a synthetic depth map with known leaves for the step.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from plantreg_gui.core.camera.rig import Rig
from plantreg_gui.core.data.landmarks import LandmarkSet

ROOT = Path(__file__).resolve().parents[1]
RES = ROOT / "resources" / "plant3dimagereg"
SCRIPTS = RES / "landmark_scripts"
DATA = ROOT.parent / "shared" / "data" / "plant3dimagereg"
needs_data = pytest.mark.skipif(not (DATA / "lidar_depthmap_np").is_dir(),
                                reason=f"the Plant3DImageReg data set is not at {DATA}")


@pytest.fixture(scope="module")
def finalize():
    sys.path.insert(0, str(SCRIPTS))
    try:
        import finalize as f
        yield f
    finally:
        sys.path.remove(str(SCRIPTS))


def _readings() -> dict:
    out: dict = {}
    for name in ("eye_readings_s11a.json", "eye_readings_s11b.json"):  # s11c: the evaluation reader's, never fitted
        out.update(json.loads((SCRIPTS / name).read_text()))
    return out


def test_a_near_leaf_margin_over_a_leaf_below_is_stepped_onto_the_near_leaf(finalize):
    """A leaf at 0.55 m covers the lower-right quadrant, a leaf at 0.67 m the rest, the margin's
    pixels are mixed (0.61 m) and the plant mask holds both leaves: the step from the corner goes
    into the near leaf and stops on it (the plant mask's centroid would have led onto the leaf
    behind)."""
    d = np.full((60, 60), 670.0)
    d[30:, 30:] = 550.0
    d[29, 29:] = d[29:, 29] = 610.0  # mixed pixels along the near leaf's margin
    uv = np.array([29.0, 29.0])
    n = finalize.front_normal(d, uv, 8.0)
    assert n[0] > 0.5 and n[1] > 0.5  # towards the near quadrant (down-right)
    step = finalize.find_step(d, uv, n)
    assert step is not None
    u, v = np.round(uv + n * step).astype(int)
    assert d[v, u] == 550.0


def test_the_held_out_rule_takes_a_seeded_third_of_the_new_thermal_pairs(finalize):
    """README "Session 11": ceil(n/3) of the kept session-11 thermal pairs, pooled over the plants,
    the same names for the same input, only thermal names, and nothing when there is nothing."""
    names = [f"0{i % 6 + 1}plant/thermal#s{i}" for i in range(7)] + ["01grapevine/hyperspectral#s9"]
    held = finalize.held_out_s11(names)
    assert len(held) == math.ceil(7 / 3) and held <= set(names[:7])
    assert finalize.held_out_s11(list(reversed(names))) == held
    assert finalize.held_out_s11([]) == set()


def test_every_session11_pair_is_the_mean_of_two_readings_that_agree():
    """landmarks_s11.json (or, once a rig is fitted to them, landmarks.json / landmarks_heldout.json):
    each point comes from a reading whose two readings agree (<= 2 px infrared, <= 4 px thermal) and
    whose reader did not drop it, and lies within the inward step (<= 10 px) of their mean."""
    rd = _readings()
    kept = {r["note"]: r for r in rd.values() if not r.get("dropped")}
    files = [RES / "landmarks_s11.json"] if (RES / "landmarks_s11.json").exists() else \
        [RES / "landmarks.json", RES / "landmarks_heldout.json"]
    rig = Rig.load(RES / "rig_nominal.json")
    seen = 0
    for f in files:
        for rec, pts in LandmarkSet.load(f, rig).recordings.items():
            for lm in pts:
                r = kept.get(lm.note)
                if r is None:
                    continue
                seen += 1
                a1, a2 = np.asarray(r["r1"]["ir"]), np.asarray(r["r2"]["ir"])
                b1, b2 = np.asarray(r["r1"]["other"]), np.asarray(r["r2"]["other"])
                assert np.linalg.norm(a1 - a2) <= 2.0 and np.linalg.norm(b1 - b2) <= 4.0, lm.note
                assert np.linalg.norm(lm.depth_uv - (a1 + a2) / 2) <= 10.5, lm.note
                (cam, uv), = lm.cameras.items()
                assert cam == "thermal" and np.linalg.norm(uv - (b1 + b2) / 2) <= 2.2 * 10.5, lm.note
    assert seen >= 1


@needs_data
def test_every_session11_pair_lies_on_the_front_surface_under_its_reading():
    """The infrared point of each kept session-11 pair has leaf depth (not the tray, not a jump:
    plantreg's own check) and lies on the nearest surface around the read feature (within 25 mm of
    the window's near depth): a margin seen over a leaf below belongs to the near leaf."""
    from plantreg_gui.core.rigfit.rigfit import check_landmark_depth

    ann = json.loads((SCRIPTS / "annotations.json").read_text())
    n = 0
    for key, items in ann.items():
        plant = key.split("/")[0]
        for it in items:
            if not str(it.get("session", "")).startswith("s11"):
                continue
            n += 1
            d = np.load(DATA / "lidar_depthmap_np" / f"{plant}.npy").astype(np.float64)
            chk = check_landmark_depth(d / 1000.0, np.asarray(it["ir"]), 1.15, snap=False)
            assert chk.status == "ok" and 0.3 < chk.z_m < 1.13, (key, it["note"], chk)
            u, v = np.round(it["feature_ir"]).astype(int)
            win = d[v - 8:v + 9, u - 8:u + 9]
            near = np.percentile(win[win > 0], 5) / 1000.0
            assert chk.z_m < near + 0.025, (key, it["note"], chk.z_m, near)
    assert n >= 1
