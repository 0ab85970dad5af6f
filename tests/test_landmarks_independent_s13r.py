"""The third reader's pairs (resources/plant3dimagereg/landmarks_independent_s13r.json, issue 23, session 13): the
s11c features' infrared points and inward steps with the s13r reader's other-camera readings. Each pair is s11c's
infrared mean moved by s11c's step, and s13r's mean of two agreeing readings (4 px) moved by the same physical
step; the readings were committed before the comparison (eye_readings_s13r.json)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from plantreg_gui.core.data.landmarks import LandmarkSet

ROOT = Path(__file__).resolve().parents[1]
RES = ROOT / "resources" / "plant3dimagereg"
sys.path.insert(0, str(RES / "landmark_scripts"))
from compare_s13r import stepped  # noqa: E402


def test_each_pair_is_s11cs_infrared_point_and_the_third_readers_mean_stepped_alike():
    mine = json.loads((RES / "landmark_scripts" / "eye_readings_s13r.json").read_text())["readings"]
    s11c = json.loads((RES / "landmark_scripts" / "eye_readings_s11c.json").read_text())["readings"]
    ls = LandmarkSet.load(RES / "landmarks_independent_s13r.json")
    assert ls.count() == len(mine) == 10
    for key, m in mine.items():
        cam, (plant, name) = m["cam"], key.split("/")
        assert np.hypot(*np.subtract(m["r1"], m["r2"])) <= 4.0
        np.testing.assert_allclose(m["mean"], np.mean([m["r1"], m["r2"]], 0), atol=1e-3)
        (lm,) = [p for p in ls.recordings[f"recordings/{plant}"] if p.note.startswith(f"s13r {name}:")]
        r = s11c[key]
        ir, oc = stepped(np.mean([r["r1"]["ir"], r["r2"]["ir"]], 0), np.asarray(m["mean"]), cam, r["inward"],
                         r["inward_step_ir_px"])
        np.testing.assert_allclose(lm.depth_uv, ir, atol=0.01)
        np.testing.assert_allclose(lm.cameras[cam], oc, atol=0.01)
