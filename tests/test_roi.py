"""The ROI against a plant's depth map (core/geometry/roi.py) and registration's warning when the ROI
cuts off most of the plant (issue 11, defect 1).

Ground truth: the synthetic demo scenes stand on a ground plane at z = GROUND_Z (1.20 m) in the
depth camera's frame; the plant (pot, soil, stems, leaves) lies in front of it. A calibration
board's box -- what the wizard's old "Fit ROI to this depth map" produced on a board pose --
puts the ground plane at 0.56 m and keeps about one leaf.

Real truth: the six Plant3DImageReg plants stand in a tray among frames and cables; the shipped
rig's hand-set ROI keeps every plant whole (looked at) and drops the tray, the floor and the
surroundings -- most of the measured depth. That must not warn.
"""

from __future__ import annotations

import numpy as np
import pytest

BOARD_ROI = (np.array([-0.4, -0.35, 0.3]), np.array([0.4, 0.35, 0.56]))


@pytest.fixture(scope="module")
def other_seed(tmp_path_factory):
    """A demo plant this module's author did not tune on (seed 3), without calibration."""
    from plantreg_gui.core.synthetic import write_demo

    folder = tmp_path_factory.mktemp("seed3") / "demo"
    write_demo(folder, seed=3, calibration=False)
    return folder


def _points(folder):
    from plantreg_gui.core.data.recording import Recording
    from plantreg_gui.core.registration.register import pixel_rays_cam
    from plantreg_gui.core.camera.rig import Rig

    rig = Rig.load(folder / "rig.json")
    rec = Recording.load(folder / "recording", rig)
    cam = rig.depth()
    return rig, rec, cam.to_rig(pixel_rays_cam(cam) * rec.depth_m(rig.depth_scale).reshape(-1, 1))


@pytest.mark.parametrize("which", ["demo", "seed3"])
def test_fit_roi_from_a_plant_depth_map_keeps_the_plant_and_drops_the_ground(which, demo_dir, other_seed):
    from plantreg_gui.core.geometry.roi import cut_fraction, cut_warning, fit_roi
    from plantreg_gui.core.synthetic import GROUND_Z

    rig, _rec, X = _points(demo_dir if which == "demo" else other_seed)
    lo, hi = fit_roi(X)
    assert GROUND_Z - 0.06 < hi[2] < GROUND_Z - 0.005  # the ground plane just in front of the ground
    assert cut_fraction(X, lo, hi)[0] < 0.02  # the plant is inside
    assert cut_warning(X, lo, hi) is None
    assert cut_warning(X, rig.roi_min, rig.roi_max) is None  # the demo rig's own ROI is right
    frac, n = cut_fraction(X, *BOARD_ROI)
    assert frac > 0.5 and n > 1000
    assert "leaves out" in cut_warning(X, *BOARD_ROI)


PLANTS = ["01grapevine", "02leopard_lily", "03areca_palm", "04philodendron", "05boston_fern", "06weeping_fig"]


def test_the_real_plants_roi_warns_only_when_it_cuts_the_plant(shared_data):
    from pathlib import Path

    from plantreg_gui.core.geometry.depth import to_metres
    from plantreg_gui.core.registration.register import pixel_rays_cam
    from plantreg_gui.core.camera.rig import Rig
    from plantreg_gui.core.geometry.roi import cut_warning

    rig = Rig.load(Path(__file__).resolve().parents[1] / "resources" / "plant3dimagereg" / "rig.json")
    cam = rig.depth()
    rays = pixel_rays_cam(cam)
    for plant in PLANTS:
        d = np.load(shared_data / "plant3dimagereg" / "lidar_depthmap_np" / f"{plant}.npy")
        X = cam.to_rig(rays * to_metres(d, rig.depth_scale).reshape(-1, 1))
        assert cut_warning(X, rig.roi_min, rig.roi_max) is None, plant
        # the same box with its ground plane among the top leaves (what a board's box did): 3 % of
        # the measured depth lies in front of it, the rest of the plant behind
        hi = rig.roi_max.copy()
        hi[2] = np.nanpercentile(X[:, 2], 3)
        w = cut_warning(X, rig.roi_min, hi)
        assert w is not None and "leaves out" in w, plant
        # a box that keeps only the left third of the view cuts the plant sideways
        hi = rig.roi_max.copy()
        hi[0] = np.nanpercentile(X[:, 0], 33)
        assert cut_warning(X, rig.roi_min, hi) is not None, plant


def test_registration_warns_when_the_roi_cuts_off_most_of_the_plant(demo_dir, tmp_path):
    from plantreg_gui.core.export.export import build_summary
    from plantreg_gui.core.registration.register import Registrar, RegistrationParams

    rig, rec, _X = _points(demo_dir)
    ok = Registrar(rig, rec)
    ok.prepare()
    assert ok.warnings == []
    bad = Registrar(rig, rec, RegistrationParams(roi_min=BOARD_ROI[0], roi_max=BOARD_ROI[1]))
    res = bad.register("ir")
    assert len(res.warnings) == 1 and "ROI" in res.warnings[0]
    assert build_summary(res, rig, rec)["warnings"] == res.warnings


def test_cli_register_prints_the_roi_warning(demo_dir, tmp_path, capsys):
    import json

    from plantreg_gui.cli import main
    from plantreg_gui.core.camera.rig import Rig

    rig = Rig.load(demo_dir / "rig.json")
    rig.roi_min, rig.roi_max = BOARD_ROI
    rig.save(tmp_path / "board_roi.rig.json")
    out = tmp_path / "out"
    rc = main(["register", "--rig", str(tmp_path / "board_roi.rig.json"), "--recording", str(demo_dir / "recording"),
               "--target", "ir", "--out", str(out), "--quiet"])
    assert rc == 0
    assert "warning: the ROI" in capsys.readouterr().err
    assert json.loads((out / "summary.json").read_text())["warnings"]
