"""Camera model and rig file against known geometry."""

import json

import numpy as np
import pytest

from plantreg_gui.core.camera.camera import Camera
from plantreg_gui.core.errors import InputError
from plantreg_gui.core.camera.rig import Rig


def _cam(**kw):
    R = np.array([[0.9998, -0.0175, 0.0], [0.0175, 0.9998, 0.0], [0.0, 0.0, 1.0]])
    R, _ = np.linalg.qr(R)
    R *= np.sign(np.diag(R))
    d = dict(name="c", modality="rgb", width=800, height=600,
             K=[[700, 0, 401.3], [0, 705, 297.8], [0, 0, 1]], dist=[-0.25, 0.09, 0.001, -0.0005, -0.01],
             R_cam_rig=R, t_cam_rig=[0.08, -0.02, 0.01])
    d.update(kw)
    return Camera(**d)


def test_project_then_ray_returns_the_point():
    cam = _cam()
    rng = np.random.default_rng(1)
    uv = rng.uniform([0, 0], [799, 599], size=(2000, 2))
    o, d = cam.rays_rig(uv)
    X = o + d * rng.uniform(0.3, 1.2, size=(len(uv), 1))
    uv2, z = cam.project(X)
    assert np.all(z > 0)
    assert np.max(np.abs(uv2 - uv)) < 1e-6


def test_pinhole_projection_matches_hand_formula():
    cam = _cam(dist=[0, 0, 0, 0, 0], R_cam_rig=np.eye(3), t_cam_rig=[0, 0, 0])
    uv, z = cam.project(np.array([[0.1, -0.05, 0.5], [0.0, 0.0, -1.0]]))
    assert uv[0] == pytest.approx([401.3 + 700 * 0.2, 297.8 - 705 * 0.1])
    assert np.all(np.isnan(uv[1])) and z[1] < 0


def test_center_and_frames():
    cam = _cam()
    assert np.allclose(cam.to_cam(cam.center_rig[None])[0], 0, atol=1e-12)
    assert cam.normalization == pytest.approx(1000 / np.sqrt(800 * 600))


def test_rig_roundtrip_keeps_unknown_keys(tmp_path):
    d = {"format": "plantreg.rig", "version": 1, "depth": {"camera": "ir", "scale": 0.001},
         "roi": {"min": [-0.45, -0.45, 0.30], "max": [0.45, 0.45, 1.17]}, "site": "greenhouse 3",
         "cameras": [{"name": "ir", "modality": "infrared", "width": 640, "height": 576,
                      "K": [[504, 0, 320], [0, 504, 288], [0, 0, 1]], "dist": [0.02, -0.01, 0, 0, 0],
                      "R": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "t": [0, 0, 0], "serial": "X1"}]}
    p = tmp_path / "rig.json"
    p.write_text(json.dumps(d))
    rig = Rig.load(p)
    assert rig.ground_z == pytest.approx(1.17) and rig.depth().name == "ir"
    rig.save(tmp_path / "out.json")
    back = json.loads((tmp_path / "out.json").read_text())
    assert back["site"] == "greenhouse 3" and back["cameras"][0]["serial"] == "X1"
    assert back["cameras"][0]["K"] == d["cameras"][0]["K"]


@pytest.mark.parametrize("mutate, words", [
    (lambda d: d.update(cameras=[]), "no cameras"),
    (lambda d: d.update(depth={"camera": "rgb"}), "depth camera 'rgb'"),
    (lambda d: d["cameras"][0].update(K=[[1, 0], [0, 1]]), "K must be"),
    (lambda d: d["cameras"][0].update(dist=[0, 0, 0]), "dist has 3"),
    # a string or null where a number belongs, NaN, a fractional pixel count: clean errors, no traceback
    (lambda d: d["depth"].update(scale="abc"), "depth.scale must be a number"),
    (lambda d: d["depth"].update(scale=None), "depth.scale must be a number"),
    (lambda d: d.update(version="one"), "version must be"),
    (lambda d: d["cameras"][0].update(dist=[float("nan"), 0, 0, 0, 0]), "finite"),
    (lambda d: d["cameras"][0].update(t=[0, float("inf"), 0]), "finite"),
    (lambda d: d["cameras"][0].update(width=10.5), "cameras[0].width must be a positive integer, got 10.5"),
    (lambda d: d.update(roi={"min": [0, 0, float("nan")], "max": [1, 1, 1]}), "roi"),
])
def test_bad_rig_files_name_the_file(tmp_path, mutate, words):
    d = {"depth": {"camera": "ir"}, "cameras": [{"name": "ir", "width": 10, "height": 10,
                                                 "K": [[5, 0, 5], [0, 5, 5], [0, 0, 1]]}]}
    mutate(d)
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(d))
    with pytest.raises(InputError) as e:
        Rig.load(p)
    assert str(p) in str(e.value) and words in str(e.value)


@pytest.mark.parametrize("planar", ["contig", "separate"])
def test_multiband_tiff_is_band_last_in_either_layout(tmp_path, planar):
    """A 5-band 40 x 30 TIFF reads as (40, 30, 5) whether its samples are pixel-interleaved or
    band-separate (GDAL's INTERLEAVE=BAND), with each band's values where they were written."""
    import tifffile

    from plantreg_gui.core.io.imageio import read_image

    cube = np.arange(40 * 30 * 5, dtype=np.float32).reshape(40, 30, 5)
    data = cube if planar == "contig" else np.moveaxis(cube, -1, 0)
    tifffile.imwrite(tmp_path / "c.tif", np.ascontiguousarray(data), planarconfig=planar, photometric="minisblack")
    back = read_image(tmp_path / "c.tif")
    assert back.shape == (40, 30, 5)
    np.testing.assert_array_equal(back, cube)
