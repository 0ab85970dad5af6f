"""Time-of-flight depth artefacts: flying pixels, denoising, the mixed-pixel flag, the realistic demo.

Ground truth comes from the synthetic generator (true mesh, exact visibility). The method's
thresholds were developed on scene seed 5, hole filling on seeds 1 and 5; the issue's figures are
asserted on seeds 0, 1, 3 and 4 (0, 3 and 4 were not looked at while developing; 1 is where the
occlusion recall fell short before hole filling). P1 coverage is also measured against what the depth
camera can observe (``observable_views``): its 98.5 % was chosen on seeds 0, 3 and 5 and checked on
seeds 8-13 (seed 11, the lowest, is asserted).
"""

import json

import numpy as np
import pytest

from plantreg_gui.core.geometry.depthfilter import clean_depth, denoise_depth, fill_holes, flying_pixels, snap_flying
from plantreg_gui.core.data.recording import Recording
from plantreg_gui.core.registration.register import RegistrationParams, register
from plantreg_gui.core.registration.cases import Case
from plantreg_gui.core.synthetic import (
    MAT_LEAF0, demo_rig, ground_truth, make_plant_scene, render_depth, render_recording,
)
from plantreg_gui.core.synthetic.render import observable_views

SEED = 0
SEEDS = (0, 1, 3, 4)


def _noise(rng, z, sa=0.001, sr=0.001):
    return z + (sa + sr * z) * rng.standard_normal(z.shape)


# ---------------------------------------------------------------------------- building blocks
def _step_scene(rng, noise=True):
    """Leaf plane at 0.8 m over ground at 1.1 m; column 40 straddles the edge with footprint
    shares f of the leaf from 0.05 to 0.95 down the rows. Returns depth, truth of mixing."""
    H, W = 60, 80
    z = np.full((H, W), 1.1)
    z[:, :40] = 0.8
    f = np.linspace(0.05, 0.95, H)
    z[:, 40] = f * 0.8 + (1 - f) * 1.1
    if noise:
        z = _noise(rng, z)
    return z.astype(np.float32), f


def test_flying_pixels_between_two_surfaces_are_found():
    rng = np.random.default_rng(1)
    for _ in range(5):
        z, f = _step_scene(rng)
        fly = flying_pixels(z)
        mid = (f >= 0.15) & (f <= 0.85)  # > 4.5 cm from either surface
        assert fly[mid, 40].all()
        plane = np.ones_like(fly)
        plane[:, 38:43] = False  # the surfaces themselves, away from the edge
        assert not fly[plane].any()


def test_steep_noisy_surfaces_are_not_flying():
    rng = np.random.default_rng(2)
    v, u = np.mgrid[0:200, 0:200]
    # at 1 m one pixel is ~2 mm: 70 degrees to the image plane = 5.5 mm of depth per pixel
    z = _noise(rng, 0.7 + 0.0055 * u + 0.001 * v).astype(np.float32)
    assert flying_pixels(z).mean() <= 0.001


def test_snapped_flying_pixel_joins_the_surface_it_mostly_saw():
    z, f = _step_scene(None, noise=False)
    fly = flying_pixels(z)
    s = snap_flying(z, fly)
    rows = np.flatnonzero(fly[:, 40])
    want = np.where(f[rows] > 0.5, 0.8, 1.1)
    np.testing.assert_allclose(s[rows, 40], want, atol=1e-6)


def test_denoise_halves_the_noise_and_never_bridges_two_leaves():
    rng = np.random.default_rng(3)
    v, u = np.mgrid[0:120, 0:160].astype(np.float64)
    truth = 0.9 + 0.0025 * u - 0.001 * v  # inclined leaf
    truth[40:80, 60:120] -= 0.02  # an upper leaf 2 cm above it
    z = _noise(rng, truth).astype(np.float32)
    out = denoise_depth(z)
    err_in, err_out = z - truth, out - truth
    assert np.std(err_out) <= 0.5 * np.std(err_in)
    # never between the two leaves: every pixel stays on its own leaf (within 4 noise sigma)
    assert np.max(np.abs(err_out)) <= 4 * (0.001 + 0.001 * 0.9)
    # the edge pixels themselves are denoised too (fit on their own side only)
    edge = np.zeros_like(truth, dtype=bool)
    edge[40, 60:120] = edge[79, 60:120] = edge[40:80, 60] = edge[40:80, 119] = True
    assert np.std(err_out[edge]) <= 0.85 * np.std(err_in[edge])  # measured 0.78: half windows, extrapolated


def test_clean_depth_switches():
    z, _f = _step_scene(np.random.default_rng(4))
    out, fly = clean_depth(z, flying=False, denoise=False)
    assert not fly.any() and np.array_equal(out, z)
    out, fly = clean_depth(z, repair=False)
    assert fly.any() and np.isnan(out[fly]).all() and np.isfinite(out[~fly]).all()


def test_fill_holes_inside_a_surface_never_across_an_edge():
    rng = np.random.default_rng(5)
    v, u = np.mgrid[0:80, 0:100].astype(np.float64)
    truth = 0.9 + 0.004 * u - 0.002 * v  # a steep leaf (4 mm per pixel)
    truth[30:50, 60:] += 0.15  # a lower surface 15 cm behind, to the right
    z = _noise(rng, truth).astype(np.float32)
    holes = rng.random(z.shape) < 0.08
    holes[10:12, 10:12] = True  # a 2 x 2 hole
    holes[30:50, 59:61] = True  # a hole band along the depth edge (column 59 leaf, 60 the surface behind)
    z[holes] = np.nan
    out, filled = fill_holes(z)
    assert not filled[~holes].any() and np.array_equal(out[~holes], z[~holes])
    inner = holes.copy()
    inner[28:52, 57:63] = False
    assert filled[inner].mean() >= 0.97  # every hole with measured same-surface neighbours around it
    # the corner pixels of the recess (30, 60) and (49, 60) lie on the leaf's diagonals and take the
    # leaf's depth (documented); everywhere else a filled depth is its own surface's
    ok = np.ones_like(filled)
    ok[29:32, 59:62] = ok[48:51, 59:62] = False
    assert np.all(np.abs(out[filled & ok] - truth[filled & ok]) <= 4 * (0.001 + 0.001 * 1.2))
    assert not filled[31:49, 60].any()  # never bridged to the surface behind
    z[:] = np.nan
    z[40, 50] = 0.9
    assert not fill_holes(z)[1].any()  # one pixel alone fills nothing


def test_clean_depth_fills_holes_but_keeps_removed_flying_pixels_removed():
    z, _f = _step_scene(np.random.default_rng(6))
    z[10, 10] = z[20, 60] = 0  # holes inside the two surfaces
    out, fly = clean_depth(z, repair=False)
    assert np.isfinite(out[10, 10]) and np.isfinite(out[20, 60])
    assert np.isnan(out[fly]).all()
    out, fly = clean_depth(z, fill=False)
    assert np.isnan(out[10, 10]) and np.isnan(out[20, 60])


# ---------------------------------------------------------------------------- the realistic scene
def _realistic(seed):
    """Scene ``seed`` with footprint-mixing flying pixels, holes, 1 mm + 0.1 % noise (the depth of
    ``render_recording(..., tof=True)``) and a thermal camera blurred with sigma 1 px. Only the
    thermal image is rendered: the figures need no other image."""
    from plantreg_gui.core.progress import ensure_reporter
    from plantreg_gui.core.synthetic.render import _render_camera, render_tof_depth
    from plantreg_gui.core.synthetic.textures import Appearance

    rig = demo_rig(thermal_blur_px=1.0)
    scene = make_plant_scene(seed)
    depth = render_tof_depth(rig, scene, (0.001, 0.001), np.random.default_rng([seed, 0]))
    i = [c.name for c in rig.cameras].index("thermal")
    thermal = _render_camera(rig.camera("thermal"), scene, Appearance(scene), None,
                             np.random.default_rng([seed, 2, i]), ensure_reporter(None))
    rec = Recording(None, depth, {"thermal": thermal})
    gt = ground_truth(rig, scene, "ir")
    return rig, scene, rec, gt


@pytest.fixture(scope="module", params=SEEDS, ids=[f"seed{s}" for s in SEEDS])
def seeded(request):
    rig, scene, rec, gt = _realistic(request.param)
    return request.param, (rig, scene, rec, gt), register(rig, rec, "ir")


@pytest.fixture(scope="module")
def realistic():
    return _realistic(SEED)


@pytest.fixture(scope="module")
def realistic_ir(realistic):
    rig, _scene, rec, _gt = realistic
    return register(rig, rec, "ir")


def test_the_realistic_depth_is_the_demos(realistic):
    """The figures' depth is exactly what ``render_recording(..., tof=True)`` (``plantreg demo``) renders."""
    from plantreg_gui.core.camera.rig import Rig

    rig, scene, rec, _gt = realistic
    small = Rig([rig.camera("ir")], rig.depth_camera, rig.depth_scale, rig.roi_min, rig.roi_max)
    demo = render_recording(small, scene, (0.001, 0.001), seed=SEED, tof=True)
    assert np.array_equal(demo.depth, rec.depth)


def _figures(rig, res, gt, src):
    from test_register import figures

    return figures(rig, res, gt, src)


def _in_roi(rig, gt):
    from test_register import in_roi

    return in_roi(rig, gt)


def test_realistic_depth_has_the_artefacts(realistic):
    rig, scene, rec, gt = realistic
    true = render_depth(rig, scene).astype(np.float64)
    d = rec.depth.astype(np.float64)
    both = (true > 0) & (d > 0)
    far_off = both & (np.abs(d - true) > 30)  # > 3 cm: between two surfaces (noise is ~2 mm)
    assert far_off.sum() > 500
    assert ((d == 0) & (true > 0)).sum() > 100  # holes on steep surfaces
    e = (d - true)[both & ~far_off]
    assert abs(1.4826 * np.median(np.abs(e - np.median(e))) - 2.0) < 0.6  # 1 mm + 0.1 % at ~1 m (robust sigma)
    assert rig.camera("thermal").extra["blur_px"] == 1.0


def test_realistic_scene_meets_the_issue_figures(seeded):
    seed, (rig, scene, rec, gt), res = seeded
    assert res.flying is not None and res.flying.shape == rig.depth().shape
    assert res.stats["flying_pixels"] == int(res.flying.sum()) > 1000
    assert res.stats["filled_pixels"] > 0
    # the same scene with clean depth, the same noise and the same holes: flying pixels must cost
    # (almost) nothing
    noisy = render_depth(rig, scene, (0.001, 0.001), np.random.default_rng([seed, 0]))
    noisy[rec.depth == 0] = 0
    ref = register(rig, Recording(None, noisy, {}), "ir")
    # the truly matchable pixels whose view of the source lies in space the depth camera observes:
    # the most that any registration from depth alone can certify (docs/registration.md section 9)
    observable = observable_views(rig, scene, gt)
    for src in res.cases:
        f = _figures(rig, res, gt, src)
        r = _figures(rig, ref, gt, src)
        match = gt.matchable[src] & _in_roi(rig, gt)
        obs = observable[src] & match
        bound = obs.sum() / match.sum()
        cov_obs = ((res.cases[src] == Case.P1) & obs).sum() / obs.sum()
        msg = f"seed {seed} {src}: {f} (clean depth, same noise: {r}; observable {bound:.4f}, P1 of them {cov_obs:.4f})"
        assert f["n_occluded"] > 1000, msg
        assert f["median"] <= 0.2 and f["p90"] <= 0.6, msg
        # P1 misses at most 1.5 % of the pixels whose view the depth camera observes; so the issue's
        # 95 % holds wherever the depth camera observes enough views (seeds 3 and 5: it does not)
        assert cov_obs >= 0.985, msg
        assert f["p1_coverage"] >= min(0.95, 0.985 * bound), msg
        assert f["p1_visible"] >= 0.997, msg
        assert f["occluded_p2_p32"] >= 0.90, msg
        assert f["occluded_p2_p32"] >= r["occluded_p2_p32"] - 0.02, msg
        assert f["p1_coverage"] >= r["p1_coverage"] - 0.01, msg


@pytest.mark.parametrize("seed", [5, 11])
def test_p1_covers_the_views_the_depth_camera_observes(seed):
    """Scenes where the issue's 95 % is out of reach (seed 5: 94.0-94.2 % of the truly matchable
    pixels have a view the depth camera observes; seed 11, not looked at while choosing 98.5 %:
    91.8-92.5 %): P1 still covers nearly all of what depth can certify, and stays right."""
    rig, scene, rec, gt = _realistic(seed)
    res = register(rig, rec, "ir")
    observable = observable_views(rig, scene, gt)
    for src in ("thermal", "hyperspectral"):
        f = _figures(rig, res, gt, src)
        match = gt.matchable[src] & _in_roi(rig, gt)
        obs = observable[src] & match
        cov_obs = ((res.cases[src] == Case.P1) & obs).sum() / obs.sum()
        msg = f"seed {seed} {src}: {f}; observable {obs.sum() / match.sum():.4f}, P1 of them {cov_obs:.4f}"
        assert obs.sum() / match.sum() < 0.95, msg  # the scene is one where 95 % cannot be reached
        assert cov_obs >= 0.985, msg  # measured 0.9918-0.9952 (seed 5), 0.9872-0.9879 (seed 11)
        assert f["p1_visible"] >= 0.997, msg


def test_without_the_clean_up_the_problem_shows(realistic, realistic_ir):
    rig, _scene, rec, gt = realistic
    off = register(rig, rec, "ir", RegistrationParams(flying_filter=False, denoise=False, fill_holes=False))
    assert off.stats["flying_pixels"] == 0 and not off.flying.any() and off.stats["filled_pixels"] == 0
    worse = 0
    for src in off.cases:
        f_off, f_on = _figures(rig, off, gt, src), _figures(rig, realistic_ir, gt, src)
        assert f_off["median"] >= 2 * f_on["median"], src  # denoising at least halves the error
        worse += f_off["occluded_p2_p32"] < f_on["occluded_p2_p32"] - 0.05
    assert worse >= 2


def _true_temperature_in_ir(rig, scene) -> np.ndarray:
    """The true surface temperature seen by each infrared pixel (NaN off the scene), (H, W)."""
    from plantreg_gui.core.synthetic.textures import Appearance

    cam = rig.camera("ir")
    o, d = cam.rays_rig()
    _t, prim, bary = scene.cast(o, d)
    hit = prim >= 0
    s = scene.surface(prim[hit], bary[hit])
    T = np.full(len(d), np.nan)
    T[hit] = Appearance(scene).temperature(s["points"], s["material"], s["uv"])
    return T.reshape(cam.shape)


def test_mean_leaf_temperature_without_mixed_pixels(seeded):
    seed, (rig, scene, _rec, gt), res = seeded
    T = _true_temperature_in_ir(rig, scene)
    leaf = gt.material >= MAT_LEAF0  # a perfect leaf segmentation of the target
    reg = res.registered["thermal"]
    p1 = (res.cases["thermal"] == Case.P1) & leaf
    mixed = res.mixed["thermal"]
    assert mixed.dtype == bool and mixed.shape == reg.shape and not (mixed & (res.cases["thermal"] != Case.P1)).any()
    sel = p1 & ~mixed
    assert sel.sum() >= 0.8 * p1.sum()
    assert abs(np.mean(reg[sel]) - np.mean(T[sel])) <= 0.05, (seed, np.mean(reg[sel]) - np.mean(T[sel]))
    # the flagged pixels are the soil-contaminated rims: clearly warmer than their true leaf
    flagged = p1 & mixed
    assert np.mean(reg[flagged]) - np.mean(T[flagged]) >= 0.2, seed
    assert res.stats["mixed_pixels"]["thermal"] == int(mixed.sum())


def test_mixed_flag_radius_follows_the_camera_blur(realistic):
    from plantreg_gui.core.registration.mixed import mixed_radius

    rig = realistic[0]
    assert mixed_radius(rig.camera("thermal"), 1.0) == pytest.approx(3.0)
    assert mixed_radius(rig.camera("rgb"), 1.0) == pytest.approx(1.0)


def test_mixed_flag_radius_includes_the_calibration_uncertainty():
    import dataclasses

    from plantreg_gui.core.registration.mixed import calibration_residual_px, mixed_radius

    rig = demo_rig(thermal_blur_px=1.0)
    th = rig.camera("thermal")
    cal = {"calibration": {"method": "landmarks", "per_camera": {"thermal": {"median_px": 2.5, "p90_px": 5.0}}}}
    assert calibration_residual_px(cal, "thermal") == pytest.approx(2.5)
    assert calibration_residual_px(cal, "rgb") == 0.0
    assert calibration_residual_px({"calibration": {"method": "board", "per_camera": {"thermal": {"median_px": 2}}}},
                                   "thermal") == 0.0  # only a landmark fit's residuals say how far off the mapping is
    assert calibration_residual_px({}, "thermal") == 0.0
    assert mixed_radius(th, 1.0, 2.5) == pytest.approx(5.5)
    keyed = dataclasses.replace(th, extra={**th.extra, "registration_px": 0.5})
    assert mixed_radius(keyed, 1.0, 2.5) == pytest.approx(3.5)  # the camera's own key wins


def test_mixed_flag_covers_a_known_calibration_error(realistic):
    """The thermal camera's pose off by 3 px (a rig fitted from a few landmarks): stating that
    uncertainty (``registration_px`` 3) keeps the soil-mixed rims out of the unflagged leaf mean."""
    import dataclasses

    from plantreg_gui.core.camera.rig import Rig

    rig, scene, rec, gt = realistic  # the thermal image rendered with the true pose
    T = _true_temperature_in_ir(rig, scene)
    leaf = gt.material >= MAT_LEAF0
    th = rig.camera("thermal")
    a = 3.0 / th.K[0, 0]  # 3 px sideways
    R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]]) @ th.R_cam_rig
    err = {}
    for reg_px in (0.0, 3.0):
        off = dataclasses.replace(th, R_cam_rig=R, t_cam_rig=-R @ th.center_rig,
                                  extra={**th.extra, "registration_px": reg_px})
        rig_off = Rig([off if c.name == "thermal" else c for c in rig.cameras], rig.depth_camera, rig.depth_scale,
                      rig.roi_min, rig.roi_max)
        res = register(rig_off, rec, "ir")
        assert res.stats["mixed_radius_px"]["thermal"] == pytest.approx(3.0 + reg_px)
        sel = (res.cases["thermal"] == Case.P1) & leaf & ~res.mixed["thermal"]
        err[reg_px] = float(np.mean(res.registered["thermal"][sel]) - np.mean(T[sel]))
    assert abs(err[3.0]) <= 0.01 and abs(err[3.0]) <= 0.5 * abs(err[0.0]), err  # measured +0.003 / +0.015


def test_noise_free_registration_is_unchanged_or_better(realistic):
    """Clean (quantised) depth: the clean-up must not make anything worse."""
    rig, scene, rec, _gt = realistic
    clean_rig = demo_rig()
    gt = ground_truth(clean_rig, scene, "ir", sources=["thermal", "rgb"])
    depth = render_depth(clean_rig, scene)
    recc = Recording(None, depth, rec.images)
    on = register(clean_rig, recc, "ir")
    off = register(clean_rig, recc, "ir", RegistrationParams(flying_filter=False, denoise=False, fill_holes=False))
    for src in ("thermal", "rgb"):
        a, b = _figures(clean_rig, on, gt, src), _figures(clean_rig, off, gt, src)
        assert a["median"] <= b["median"] + 0.005 and a["p90"] <= b["p90"] + 0.01, (src, a, b)
        assert a["p1_visible"] >= b["p1_visible"] - 0.0005, (src, a, b)
        assert a["p1_coverage"] >= b["p1_coverage"] - 0.003, (src, a, b)
        assert a["occluded_p2_p32"] >= b["occluded_p2_p32"] - 0.015, (src, a, b)
    assert np.isin(on.cases["thermal"], [Case.P1, Case.P2, Case.P32]).any()


# ---------------------------------------------------------------------------- CLI and outputs
def _run(argv):
    import contextlib
    import io

    from plantreg_gui import cli

    o, e = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(o), contextlib.redirect_stderr(e):
        code = cli.main([str(a) for a in argv])
    return code, o.getvalue(), e.getvalue()


def test_register_writes_edge_masks_flying_mask_and_counts(demo_dir, tmp_path):
    import plyfile

    from plantreg_gui.core.io.imageio import read_image

    out = tmp_path / "out"
    code, so, se = _run(["register", "--rig", demo_dir / "rig.json", "--recording", demo_dir / "recording",
                         "--target", "ir", "--out", out, "--quiet", "--mixed-radius", "1.5"])
    assert code == 0, se
    assert "flying pixels" in so and "mixed (% of P1)" in so
    s = json.loads((out / "summary.json").read_text())
    assert s["version"] == 2 and s["parameters"]["mixed_radius_px"] == 1.5
    assert s["parameters"]["fill_holes"] is True and s["tof"]["filled_pixels"] >= 0
    for cam in ("rgb", "thermal", "hyperspectral"):  # the clean demo: no blur_px, no landmark fit
        assert s["tof"]["mixed"][cam]["radius_px"] == pytest.approx(1.5)
    assert s["parameters"]["flying_filter"] is True and s["parameters"]["denoise"] is True
    fly = read_image(out / "flying.png")
    assert fly.shape == (576, 640) and set(np.unique(fly)) <= {0, 255}
    assert s["tof"]["flying_pixels"] == int((fly == 255).sum())
    v = plyfile.PlyData.read(str(out / "pointcloud.ply"))["vertex"]
    for cam in ("rgb", "thermal", "hyperspectral"):
        edge = read_image(out / f"cases/{cam}_edge.png")
        case = read_image(out / f"cases/{cam}.png")
        assert edge.shape == case.shape and set(np.unique(edge)) <= {0, 255}
        assert np.all(case[edge == 255] == Case.P1)  # today's case codes unchanged; the flag is extra
        assert s["tof"]["mixed"][cam]["pixels"] == int((edge == 255).sum()) > 0
        r, c = np.asarray(v["row"]), np.asarray(v["col"])
        assert np.array_equal(np.asarray(v[f"{cam}_mixed"]) == 1, edge[r, c] == 255)


def test_register_tof_switches_and_drop_mixed(demo_dir, tmp_path):
    from plantreg_gui.core.io.imageio import read_image

    out = tmp_path / "out"
    code, so, se = _run(["register", "--rig", demo_dir / "rig.json", "--recording", demo_dir / "recording",
                         "--target", "ir", "--out", out, "--quiet", "--no-flying-filter", "--no-denoise",
                         "--no-fill-holes", "--drop-mixed"])
    assert code == 0, se
    s = json.loads((out / "summary.json").read_text())
    assert s["parameters"]["flying_filter"] is False and s["parameters"]["denoise"] is False
    assert s["parameters"]["fill_holes"] is False and s["tof"]["filled_pixels"] == 0
    assert s["tof"]["flying_pixels"] == 0 and s["tof"]["flying_handling"] == "off"
    assert "--no-flying-filter" in s["inputs"]["command"] and "--drop-mixed" in s["inputs"]["command"]
    edge = read_image(out / "cases/thermal_edge.png") == 255
    th = read_image(out / "registered/thermal.tif")
    assert edge.any() and np.isnan(th[edge]).all()
    code, so, se = _run(["register", "--rig", demo_dir / "rig.json", "--recording", demo_dir / "recording",
                         "--target", "ir", "--out", tmp_path / "bad", "--denoise-size", "4"])
    assert code == 1 and "--denoise-size" in se and "Traceback" not in se and len(se.strip().splitlines()) == 1
    assert not (tmp_path / "bad").exists()


def test_demo_command_has_a_clean_option(demo_dir):
    manifest = json.loads((demo_dir / "recording" / "recording.json").read_text())
    assert manifest["synthetic"]["tof_artefacts"] is False and manifest["synthetic"]["depth_noise"] == [0.0, 0.0]
    from plantreg_gui.cli.demo_cmd import add_parser
    import argparse

    p = argparse.ArgumentParser()
    add_parser(p.add_subparsers())
    assert p.parse_args(["demo", "x", "--clean"]).clean and not p.parse_args(["demo", "x"]).clean


def test_write_demo_is_realistic_by_default(tmp_path, monkeypatch):
    """`plantreg demo` renders the ToF artefacts and a blurred thermal camera unless --clean."""
    from plantreg_gui.core.synthetic import demo as demo_mod

    seen = []

    class Stop(Exception):
        pass

    def fake_render(rig, scene, depth_noise=(0.0, 0.0), seed=0, progress=None, **kw):
        seen.append((rig.camera("thermal").extra.get("blur_px"), tuple(depth_noise), kw.get("tof")))
        raise Stop

    monkeypatch.setattr(demo_mod, "render_recording", fake_render)
    for clean in (False, True):
        with pytest.raises(Stop):
            demo_mod.write_demo(tmp_path / f"d{clean}", calibration=False, clean=clean)
    assert seen == [(1.0, (0.001, 0.001), True), (None, (0.0, 0.0), False)]
    assert not list(tmp_path.iterdir())  # nothing half-written


# ---------------------------------------------------------------------------- the depth camera as a source
@pytest.mark.parametrize("seed", [11, 12])
def test_depth_camera_as_a_source_sees_its_own_surface(seed):
    """Registering into another camera, the depth camera's own pixels are never P3.2 where it truly
    sees the point: its blind space (the uncertainty mesh's curtains, in planes through its centre)
    cannot lie between it and its own surface. Segments starting exactly at its centre made
    Embree report grazing hits there: 0.1-0.7 % of its P1 pixels were P3.2, all truly visible
    (seeds 3, 5, 9 while fixing; these seeds were not looked at)."""
    from plantreg_gui.core.synthetic.render import render_tof_depth

    rig = demo_rig()
    scene = make_plant_scene(seed)
    depth = render_tof_depth(rig, scene, (0.001, 0.001), np.random.default_rng([seed, 0]))
    rec = Recording(None, depth, {})
    for target in ("thermal", "rgb"):
        res = register(rig, rec, target)
        gt = ground_truth(rig, scene, target)
        cases = res.cases[rig.depth_camera]
        p1 = (cases == Case.P1).sum()
        wrong = ((cases == Case.P32) & gt.visible[rig.depth_camera]).sum()
        assert wrong <= max(5, 1e-4 * p1), (target, int(wrong), int(p1))
