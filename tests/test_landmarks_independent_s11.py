"""The independent readers' pairs (resources/plant3dimagereg/landmarks_independent_s11.json, read in session 11c,
and landmarks_s13.json, read in session 13; both held out of every fit): every kept
pair is the mean of two readings that agree within the protocol's tolerance (2 px infrared, 4 px other camera),
moved only along its stated inward direction, and its infrared point lies on leaf depth by plantreg's own check
(not the ground, not a flying pixel) -- the properties that make it usable as held-out ground truth."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from plantreg_gui.core.camera.rig import Rig
from plantreg_gui.core.data.landmarks import LandmarkSet
from plantreg_gui.core.data.recording import Recording
from plantreg_gui.core.rigfit.rigfit import check_landmark_depth

ROOT = Path(__file__).resolve().parents[1]
RES = ROOT / "resources" / "plant3dimagereg"
DATA = ROOT.parent / "shared" / "data" / "plant3dimagereg"
TOL = {"ir": 2.0, "thermal": 4.0, "hyperspectral": 4.0}
SCALE = {"thermal": 2.0, "hyperspectral": 1.8}  # other-camera px per infrared px of the inward step
# landmarks file -> (its eye readings, the session prefix of each point's note, the fewest kept pairs)
SETS = {"landmarks_independent_s11.json": ("eye_readings_s11c.json", "s11c", 8),
        "landmarks_s13.json": ("eye_readings_s13.json", "s13", 1)}


def _readings(f):
    return json.loads((RES / "landmark_scripts" / SETS[f][0]).read_text())["readings"]


def _kept(f=None):
    return [(g, k, r) for g in ([f] if f else SETS) for k, r in _readings(g).items() if r.get("kept")]


@pytest.mark.parametrize("f", sorted(SETS))
def test_the_file_loads_and_names_only_the_rigs_cameras(f):
    rig = Rig.load(RES / "rig_nominal.json")
    ls = LandmarkSet.load(RES / f, rig, check_recordings=True)
    assert ls.count() == len(_kept(f)) >= SETS[f][2]
    assert set(ls.camera_names) <= {"thermal", "hyperspectral"}


@pytest.mark.parametrize("f,key,r", _kept(), ids=[f"{f}:{k}" for f, k, _ in _kept()])
def test_each_pair_is_the_mean_of_two_agreeing_readings_moved_along_its_inward_direction(f, key, r):
    cam = r.get("cam", "thermal")
    for c in ("ir", cam):
        assert np.hypot(*np.subtract(r["r1"][c], r["r2"][c])) <= TOL[c]
    ls = LandmarkSet.load(RES / f)
    plant, name = key.split("/")
    (lm,) = [p for p in ls.recordings[f"recordings/{plant}"] if p.note.startswith(f"{SETS[f][1]} {name}:")]
    d = np.asarray(r["inward"], float) / np.linalg.norm(r["inward"])
    step = r["inward_step_ir_px"]
    assert 0 <= step <= 6
    np.testing.assert_allclose(lm.depth_uv, np.mean([r["r1"]["ir"], r["r2"]["ir"]], 0) + step * d, atol=0.01)
    # thermal is turned ~90 deg clockwise of the infrared, hyperspectral ~90 deg anticlockwise
    dt = np.array([-d[1], d[0]]) if cam == "thermal" else np.array([d[1], -d[0]])
    np.testing.assert_allclose(lm.cameras[cam], np.mean([r["r1"][cam], r["r2"][cam]], 0) + SCALE[cam] * step * dt,
                               atol=0.01)


@pytest.mark.skipif(not (DATA / "lidar_depthmap_np").is_dir(), reason=f"the Plant3DImageReg data set is not at {DATA}")
@pytest.mark.parametrize("f", sorted(SETS))
def test_every_infrared_point_reads_the_leaf_not_the_ground(f):
    rig = Rig.load(RES / "rig_nominal.json")
    ls = LandmarkSet.load(RES / f)
    for key, pts in ls.recordings.items():
        depth = Recording.load(ls.folder(key), rig).depth_m(rig.depth_scale)
        for lm in pts:
            chk = check_landmark_depth(depth, lm.depth_uv, rig.ground_z)
            assert chk.status == "ok", (key, lm.note, chk)
            # the plants' leaves lie at 0.45-1.12 m; the tray's floor (the ground) at 1.18-1.24 m
            assert 0.45 < chk.z_m < 1.12, (key, lm.note, chk.z_m)
