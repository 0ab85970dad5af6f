"""The shipped Plant3DImageReg resources (resources/plant3dimagereg): recordings, rigs, landmarks.

File-format checks run everywhere; the checks that read the real images need the data set beside
the project (``../shared/data/plant3dimagereg``) and say so when it is absent.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from plantreg_gui.core.data.landmarks import LandmarkSet
from plantreg_gui.core.camera.rig import Rig

ROOT = Path(__file__).resolve().parents[1]
RES = ROOT / "resources" / "plant3dimagereg"
PLANTS = ["01grapevine", "02leopard_lily", "03areca_palm", "04philodendron", "05boston_fern", "06weeping_fig"]
DATA = ROOT.parent / "shared" / "data" / "plant3dimagereg"
needs_data = pytest.mark.skipif(not (DATA / "lidar_depthmap_np").is_dir(),
                                reason=f"the Plant3DImageReg data set is not at {DATA}")


@pytest.mark.parametrize("name", ["rig_nominal.json", "rig.json"])
def test_rigs_load_with_the_three_cameras(name):
    rig = Rig.load(RES / name)
    assert rig.names == ["ir", "thermal", "hyperspectral"]
    assert rig.depth_camera == "ir" and rig.depth_scale == 0.001
    assert [rig.camera(n).shape for n in rig.names] == [(576, 640), (480, 640), (512, 512)]
    assert rig.camera("thermal").extra["units"] == "degC"
    # the ROI's max z is the ground plane: below the plants (>= 1.05 m seen) and above the tray's near side
    assert 1.05 < rig.ground_z < 1.25


def test_recordings_point_into_the_shared_data_set_with_relative_paths():
    for p in PLANTS:
        m = json.loads((RES / "recordings" / p / "recording.json").read_text())
        paths = [m["depth"], *m["images"].values()]
        assert set(m["images"]) == {"ir", "thermal", "hyperspectral"}
        assert all(not Path(x).is_absolute() for x in paths)
        assert m["images"]["thermal"].endswith(f"thermal_np_01/{p}.npy")  # degrees C, not the display PNG
        resolved = [(RES / "recordings" / p / x).resolve() for x in paths]
        assert all(r.is_relative_to(DATA.resolve()) for r in resolved)


def test_landmarks_file_is_valid_for_the_rig():
    rig = Rig.load(RES / "rig_nominal.json")
    ls = LandmarkSet.load(RES / "landmarks.json", rig, check_recordings=True)
    assert ls.count() >= 20
    assert set(ls.camera_names) == {"thermal", "hyperspectral"}
    assert all(k.startswith("recordings/") for k in ls.recordings)
    assert all(lm.note for pts in ls.recordings.values() for lm in pts)


def test_landmarks_agree_with_the_two_eye_readings():
    """Every landmark comes from two readings that agree (landmark_scripts/finalize.py) and lies a few pixels
    inside the read feature (the inward step onto valid depth)."""
    ann = json.loads((RES / "landmark_scripts" / "annotations.json").read_text())
    for items in ann.values():
        for it in items:
            step = np.linalg.norm(np.subtract(it["ir"], it["feature_ir"]))
            assert step <= 10.5 and abs(step - it["inward_step_ir_px"]) < 0.6


@needs_data
def test_every_recording_loads_against_the_fitted_rig():
    from plantreg_gui.core.data.recording import Recording

    rig = Rig.load(RES / "rig.json")
    for p in PLANTS:
        rec = Recording.load(RES / "recordings" / p, rig)
        assert rec.images["thermal"].dtype == np.float64 and 10 < np.nanmedian(rec.images["thermal"]) < 30


@needs_data
def test_landmarks_sit_on_valid_plant_depth_and_the_fitted_rig_explains_the_hyperspectral_ones():
    from plantreg_gui.core.rigfit.rigfit import evaluate_landmarks, landmark_depth, load_recording_landmarks

    rig = Rig.load(RES / "rig.json")
    recs = load_recording_landmarks(rig, LandmarkSet.load(RES / "landmarks.json", rig))
    for r in recs:
        for lm in r.points:
            z, why = landmark_depth(r.depth_m, lm.depth_uv)
            assert np.isfinite(z) and 0.3 < z < 1.15, (r.name, lm.note, why)
    rows, rejected = evaluate_landmarks(rig, recs, ["hyperspectral"])
    assert not rejected
    res = np.array([d["residual_px"] for d in rows])
    # measured: median 2.6 px, max 4.8 px (README); reading uncertainty ~1 px per reading
    assert len(res) >= 15 and np.median(res) < 3.5 and res.max() < 8.0


def test_heldout_landmarks_are_valid_and_were_kept_out_of_the_fit():
    """landmarks_heldout.json: pairs read after rig.json was fitted (landmark_scripts/build_landmarks.py writes
    the annotations marked "held_out" there); rig.json's fit used landmarks.json alone."""
    rig = Rig.load(RES / "rig_nominal.json")
    held = LandmarkSet.load(RES / "landmarks_heldout.json", rig, check_recordings=True)
    fit = LandmarkSet.load(RES / "landmarks.json", rig)
    assert held.count() >= 1 and set(held.camera_names) == {"thermal"}
    used = {(k, tuple(np.round(lm.depth_uv, 2)), c) for k, pts in fit.recordings.items() for lm in pts for c in lm.cameras}
    assert not any((k, tuple(np.round(lm.depth_uv, 2)), c) in used
                   for k, pts in held.recordings.items() for lm in pts for c in lm.cameras)
    assert json.loads((RES / "rig.json").read_text())["calibration"]["landmarks_used"] == fit.count()


def _heldout_by_kind(rig: Rig) -> dict[str, list]:
    """landmarks_heldout.json's points by ``"held_out_kind"``, as (recording, Landmark)."""
    held = LandmarkSet.load(RES / "landmarks_heldout.json", rig)
    out: dict[str, list] = {}
    for k, pts in held.recordings.items():
        for lm in pts:
            out.setdefault(lm.extra.get("held_out_kind"), []).append((k, lm))
    return out


def test_heldout_pairs_say_how_they_were_found():
    """README, "Session landmarks": 5 pairs located with rig.json's predictions in view (session
    land12; no independent check) and 2 read on crops without any mark of a rig's prediction."""
    kinds = _heldout_by_kind(Rig.load(RES / "rig_nominal.json"))
    assert set(kinds) == {"found_with_rig", "independent"}
    assert len(kinds["found_with_rig"]) == 5 and len(kinds["independent"]) == 2


def test_the_independent_heldout_pairs_are_the_mean_of_two_readings_within_1_5_px():
    """Ground truth for the independent pairs is the eye readings: two readings on different crops
    and zooms, without a rig's prediction in view, agree within 1.5 px in each image, and the
    held-out landmark is their mean (both points on valid depth as read: no inward move)."""
    readings = json.loads((RES / "landmark_scripts" / "eye_readings.json").read_text())
    indep = {k: r for k, r in readings.items() if r.get("held_out_kind") == "independent"}
    assert len(indep) == 2
    kinds = _heldout_by_kind(Rig.load(RES / "rig_nominal.json"))
    for key, r in indep.items():
        assert "without any mark of a rig's prediction" in r["held_out"]
        for cam in ("ir", "other"):
            assert np.linalg.norm(np.subtract(r["r1"][cam], r["r2"][cam])) <= 1.5, (key, cam)
        plant, cam = key.split("#")[0].split("/")
        match = [lm for k, lm in kinds["independent"] if k == f"recordings/{plant}" and lm.note == r["note"]]
        assert len(match) == 1, key
        assert np.allclose(match[0].depth_uv, np.mean([r["r1"]["ir"], r["r2"]["ir"]], axis=0), atol=0.01)
        assert np.allclose(match[0].cameras[cam], np.mean([r["r1"]["other"], r["r2"]["other"]], axis=0), atol=0.01)


@needs_data
def test_the_fitted_rig_predicts_the_heldout_thermal_landmarks_found_with_its_help():
    """The 5 held-out pairs of session land12: never fitted, but located with rig.json's predictions
    in view, so they flatter it (README, "Session landmarks"). Measured: 1.3-5.8 px, median 3.6 px;
    the bounds leave ~1.5 px for reading noise."""
    from plantreg_gui.core.rigfit.rigfit import RecordingLandmarks, evaluate_landmarks, load_recording_landmarks

    rig = Rig.load(RES / "rig.json")
    recs = load_recording_landmarks(rig, LandmarkSet.load(RES / "landmarks_heldout.json", rig))
    recs = [RecordingLandmarks(r.name, r.depth_m, [lm for lm in r.points if lm.extra["held_out_kind"] == "found_with_rig"])
            for r in recs]
    rows, rejected = evaluate_landmarks(rig, [r for r in recs if r.points], ["thermal"])
    res = np.array([d["residual_px"] for d in rows])
    assert not rejected and len(res) == 5
    assert np.median(res) < 5.0 and res.max() < 8.0


@needs_data
def test_the_fitted_rig_misses_the_independent_heldout_pairs_by_the_documented_figures():
    """The 2 pairs read without a rig's prediction in view measure the shipped thermal pose where
    it was not fitted, and they are large (README, "Session landmarks": 6.62 px grapevine top-leaf
    notch, 14.21 px weeping fig curled leaf; issue 23's 4 px goal is not reached). The bounds guard
    the documented figures with ~1.5 px for reading noise: a rig.json that did worse would make the
    README's figures untrue."""
    from plantreg_gui.core.rigfit.rigfit import RecordingLandmarks, evaluate_landmarks, load_recording_landmarks

    rig = Rig.load(RES / "rig.json")
    recs = load_recording_landmarks(rig, LandmarkSet.load(RES / "landmarks_heldout.json", rig))
    recs = [RecordingLandmarks(r.name, r.depth_m, [lm for lm in r.points if lm.extra["held_out_kind"] == "independent"])
            for r in recs]
    rows, rejected = evaluate_landmarks(rig, [r for r in recs if r.points], ["thermal"])
    res = {d["recording"].split("/")[-1]: d["residual_px"] for d in rows}
    assert not rejected and set(res) == {"01grapevine", "06weeping_fig"}
    assert res["01grapevine"] < 8.0 and res["06weeping_fig"] < 15.7
