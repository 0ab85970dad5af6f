"""Silhouette (outline) pose fit against synthetic truth (core/rigfit/silhouette.py).

The demo rig renders two plants; the start rig is the truth with every source camera rotated by
2 degrees and moved by 2 cm (random axes); the fit sees only the depth map and the source images
(no landmarks). Error = pixel distance between the plant's outline points projected by the
fitted and by the true camera. Scene and perturbation seeds differ from the ones the module was
developed on (scenes 1, 2, perturbation 0).
"""

from __future__ import annotations

import numpy as np
import pytest

from plantreg_gui.core.rigfit import silhouette as S
from plantreg_gui.core.errors import InputError
from plantreg_gui.core.errors import Cancelled
from plantreg_gui.core.progress import CancelToken, Reporter
from plantreg_gui.core.camera.rig import Rig
from plantreg_gui.core.synthetic import demo_rig, make_plant_scene
from plantreg_gui.core.synthetic.landmarks import perturb_rig
from plantreg_gui.core.synthetic.render import render_recording

SCENES = (5, 6)


@pytest.fixture(scope="module")
def setup():
    d = demo_rig().to_dict()
    d["cameras"] = [c for c in d["cameras"] if c["name"] != "hyperspectral"]  # speed: rgb + thermal suffice
    rig = Rig.from_dict(d)
    recs = [render_recording(rig, make_plant_scene(s), seed=s, supersample=1) for s in SCENES]
    return rig, recs


def _views(start, cam, rig, recs):
    return [S.make_view(start, cam, f"scene{s}", r.depth_m(rig.depth_scale), r.images[cam])
            for s, r in zip(SCENES, recs)]


@pytest.mark.parametrize("cam, limit_px", [("rgb", 0.5), ("thermal", 1.0)])
def test_outline_fit_recovers_the_pose(setup, cam, limit_px):
    rig, recs = setup
    start = perturb_rig(rig, np.random.default_rng(7), rotation_deg=2.0, position_m=0.02, focal_rel=0.0)
    views = _views(start, cam, rig, recs)
    res = S.fit_camera(start, cam, views)
    X = np.concatenate([v.X_rig for v in views])
    truth = rig.camera(cam).project(X)[0]
    e0 = np.linalg.norm(start.camera(cam).project(X)[0] - truth, axis=1)
    e1 = np.linalg.norm(res.camera.project(X)[0] - truth, axis=1)
    assert np.median(e0) > 5.0  # the start is really off
    assert np.median(e1) <= limit_px, (np.median(e0), np.median(e1))
    assert np.percentile(e1, 90) <= 2 * limit_px


def test_landmarks_alone_need_six_and_cancel_is_honoured(setup):
    rig, recs = setup
    views = _views(rig, "thermal", rig, recs)
    with pytest.raises(InputError, match="fewer than the 6"):
        S.fit_camera(rig, "thermal", views, use_silhouette=False)
    tok = CancelToken()
    tok.cancel()
    with pytest.raises(Cancelled):
        S.fit_camera(rig, "thermal", views, progress=Reporter(None, tok))


def test_signed_distance_zero_between_plant_and_background():
    m = np.zeros((20, 20), bool)
    m[5:15, 5:15] = True
    sdf = S.signed_distance(m)
    assert sdf[10, 10] < -4 and sdf[0, 0] > 4
    # bilinear zero crossing half-way between pixel 14 (plant) and 15 (background)
    assert sdf[10, 14] == pytest.approx(-0.5) and sdf[10, 15] == pytest.approx(0.5)


def test_cli_fit_rig_silhouette_without_landmarks(setup, tmp_path, capsys):
    """``plantreg fit-rig --silhouette`` with a landmarks file without points: the images alone."""
    from plantreg_gui import cli
    from plantreg_gui.core.data.landmarks import LandmarkSet

    rig, recs = setup
    ls = LandmarkSet(base=tmp_path)
    for s, r in zip(SCENES, recs):
        r.save(tmp_path / "recordings" / f"plant{s}")
        ls.recordings[f"recordings/plant{s}"] = []
    ls.save(tmp_path / "landmarks.json")
    start = perturb_rig(rig, np.random.default_rng(8), rotation_deg=2.0, position_m=0.02, focal_rel=0.0)
    start.save(tmp_path / "start.json")
    out = tmp_path / "fitted.json"
    code = cli.main(["fit-rig", "--rig", str(tmp_path / "start.json"), "--landmarks", str(tmp_path / "landmarks.json"),
                     "--out", str(out), "--silhouette", "--quiet"])
    stdout, err = capsys.readouterr()
    assert code == 0, err
    assert "silhouette fit" in stdout and "thermal" in stdout
    fitted = Rig.load(out)
    assert fitted.extra["calibration"]["method"] == "silhouette"
    X = np.concatenate([_views(rig, "rgb", rig, recs)[i].X_rig for i in range(len(recs))])  # the plants' outlines
    for cam in ("rgb", "thermal"):
        e = np.linalg.norm(fitted.camera(cam).project(X)[0] - rig.camera(cam).project(X)[0], axis=1)
        assert np.median(e) <= 1.0, (cam, np.median(e))
