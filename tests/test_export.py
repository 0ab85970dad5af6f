"""The output folder of a registration, written from a hand-made result with known content."""

import json
import os
from pathlib import Path

import cv2
import numpy as np
import pytest
import tifffile
from plyfile import PlyData

from plantreg_gui.core.export import export, tiffs
from plantreg_gui.core.camera.camera import Camera
from plantreg_gui.core.display.display import BACKGROUND_RGB
from plantreg_gui.core.errors import Cancelled, InputError
from plantreg_gui.core.export.export import OUTPUTS, write_outputs
from plantreg_gui.core.progress import CancelToken, Reporter
from plantreg_gui.core.data.recording import Recording
from plantreg_gui.core.registration.register import RegistrationParams, RegistrationResult
from plantreg_gui.core.camera.rig import Rig

H, W = 30, 40
R0, R1, C0, C1 = 5, 25, 8, 32  # the object: rows R0..R1-1, cols C0..C1-1 (20 x 24 = 480 pixels)
NB = 12                        # hyperspectral bands


def _rig():
    K = lambda f, w, h: [[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]]  # noqa: E731
    cams = [
        Camera("ir", "infrared", W, H, K(40, W, H)),
        Camera("rgb", "rgb", 80, 60, K(80, 80, 60), t_cam_rig=[-0.05, 0, 0]),
        Camera("thermal", "thermal", 32, 24, K(30, 32, 24), t_cam_rig=[0.05, 0, 0]),
        Camera("hs", "hyperspectral", 20, 20, K(20, 20, 20), t_cam_rig=[0, 0.05, 0]),
    ]
    return Rig(cams, depth_camera="ir", depth_scale=0.001, roi_min=[-1, -1, 0.2], roi_max=[1, 1, 1.5])


def _result():
    """A result whose every array is known: a plane at z = 1 m seen by the ir target."""
    rig = _rig()
    obj = np.zeros((H, W), bool)
    obj[R0:R1, C0:C1] = True
    o, d = rig.camera("ir").rays_rig()
    pts = (o + d / d[:, 2:3] * 1.0).reshape(H, W, 3).astype(np.float32)
    pts[~obj] = np.nan
    pts[R0, C0, 2] = np.nan  # one point with a single NaN coordinate: must be dropped too
    rows, cols = np.mgrid[0:H, 0:W]
    ir = (100.0 + rows + 0.01 * cols).astype(np.float32)                       # every pixel (target)
    rgb = np.full((H, W, 3), np.nan, np.float32)
    rgb[obj] = (0, 0, 0)
    left = obj & (cols < 20)
    rgb[left] = (255, 0, 0)                 # red left half, black right half: stretch is identity
    rgb[obj & (cols >= 20), 1] = 255        # green right half
    thermal = np.where(obj, 20.0 + 0.1 * cols, np.nan).astype(np.float32)
    thermal[R0:R0 + 2] = np.nan             # two rows not mapped in the thermal camera
    hs = np.where(obj[..., None], np.arange(NB, dtype=np.float32) * 100 + rows[..., None], np.nan).astype(np.float32)
    area = np.full((H, W), 6, np.uint8)
    area[obj] = 4
    area[R1 - 1, C0:C1] = 5
    cases = {}
    for k, cam in enumerate(("rgb", "thermal", "hs")):
        c = np.zeros((H, W), np.uint8)
        c[obj] = 1
        c[R0 + k, C0:C0 + 5] = 2     # 5 P2 pixels
        c[R0 + 10, C0:C0 + 3] = 3    # 3 P3.1
        c[R0 + 11, C0:C0 + 4] = 4    # 4 P3.2
        c[R1 - 1, C0:C1] = 5         # 24 P5
        c[R0 + 12, C1 - 2:C1] = 6    # 2 outside
        cases[cam] = c
    res = RegistrationResult(
        target="ir", points_rig=pts, area=area,
        registered={"ir": ir, "rgb": rgb, "thermal": thermal, "hs": hs},
        source_uv={}, cases=cases, params=RegistrationParams(edge_angle_deg=12.5),
        timings={"mesh": 0.01, "raycast": 0.02}, stats={"triangles": np.int64(1234)},
    )
    return rig, res


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    rig, res = _result()
    out = tmp_path_factory.mktemp("export") / "out"
    rec = Recording(folder=None, depth=None, images={})
    ret = write_outputs(res, rig, rec, out, inputs={"rig": Path("/data/rig.json")})
    assert ret == out
    return rig, res, out


def test_every_file_of_the_layout_is_there(written):
    _, _, out = written
    files = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
    assert files == sorted(
        [f"registered/{c}.{e}" for c in ("ir", "rgb", "thermal", "hs") for e in ("tif", "png")]
        + [f"cases/{c}.png" for c in ("rgb", "thermal", "hs")]
        + ["areas.png", "pointcloud.ply", "mosaic.png", "summary.json"]
    )
    assert not [p for p in out.parent.iterdir() if p.name != "out"]  # no temp folders left


def test_registered_tiffs_are_float32_target_sized_with_nan(written):
    _, res, out = written
    for cam, ref in res.registered.items():
        with tifffile.TiffFile(out / f"registered/{cam}.tif") as t:
            assert len(t.pages) == 1                                  # bands are samples, not pages
            a = t.asarray()
        assert a.dtype == np.float32 and a.shape == ref.shape
        assert a.shape[:2] == (H, W)
        assert np.array_equal(a, ref, equal_nan=True)
    hs = tifffile.imread(out / "registered/hs.tif")
    assert hs.shape == (H, W, NB) and np.isnan(hs[0, 0]).all() and hs[R0 + 3, C0 + 1, 7] == 700 + R0 + 3


def test_case_and_area_pngs(written):
    _, res, out = written
    for cam, ref in res.cases.items():
        a = cv2.imread(str(out / f"cases/{cam}.png"), cv2.IMREAD_UNCHANGED)
        assert a.dtype == np.uint8 and np.array_equal(a, ref)
    assert not (out / "cases/ir.png").exists()   # the target is no source
    a = cv2.imread(str(out / "areas.png"), cv2.IMREAD_UNCHANGED)
    assert a.dtype == np.uint8 and np.array_equal(a, res.area)


def test_previews_and_mosaic(written):
    _, _, out = written
    th = cv2.cvtColor(cv2.imread(str(out / "registered/thermal.png")), cv2.COLOR_BGR2RGB).astype(int)
    assert th.shape == (H, W, 3)
    assert tuple(th[0, 0]) == BACKGROUND_RGB and tuple(th[R0, C0 + 3]) == BACKGROUND_RGB  # not mapped
    cold, hot = th[R0 + 5, C0], th[R0 + 5, C1 - 1]
    assert cold[2] > cold[0] + 50 and hot[0] > hot[2] + 50    # diverging blue -> red
    hs = cv2.imread(str(out / "registered/hs.png"))
    assert hs.shape == (H, W, 3) and len(np.unique(hs[R0:R1, C0:C1, 2])) > 5  # PCA varies with row
    m = cv2.imread(str(out / "mosaic.png"))
    assert m.shape == (H, W, 3)
    # tile (0, 0) is the target's preview, tile (0, 1) the next camera's (tile = 8 px here)
    ir = cv2.imread(str(out / "registered/ir.png"))
    rgb = cv2.imread(str(out / "registered/rgb.png"))
    assert np.array_equal(m[:8, :8], ir[:8, :8]) and np.array_equal(m[:8, 8:16], rgb[:8, 8:16])


def test_ply_has_the_hits_with_every_cameras_values(written):
    _, res, out = written
    v = PlyData.read(str(out / "pointcloud.ply"))["vertex"]
    n = (R1 - R0) * (C1 - C0) - 1      # one point had a NaN z
    assert v.count == n
    names = [p.name for p in v.properties]
    assert names[:6] == ["x", "y", "z", "red", "green", "blue"]
    assert {"ir", "rgb_b000", "rgb_b001", "rgb_b002", "thermal", "rgb_case", "thermal_case", "hs_case"} <= set(names)
    assert [f"hs_b{i:03d}" for i in range(NB)] == [s for s in names if s.startswith("hs_b")]
    rows, cols = np.asarray(v["row"]), np.asarray(v["col"])
    assert np.all((rows >= R0) & (rows < R1) & (cols >= C0) & (cols < C1))
    assert not np.any((rows == R0) & (cols == C0))
    np.testing.assert_allclose(v["z"], 1.0, atol=1e-6)
    np.testing.assert_allclose(v["thermal"][rows >= R0 + 2], 20.0 + 0.1 * cols[rows >= R0 + 2], rtol=1e-6)
    assert np.all(np.isnan(v["thermal"][rows < R0 + 2]))
    np.testing.assert_allclose(v["hs_b005"], 500.0 + rows)
    np.testing.assert_allclose(v["ir"], 100.0 + rows + 0.01 * cols, rtol=1e-6)
    # colours: the rgb camera's rendering (red left, green right)
    red, green, blue = (np.asarray(v[c]) for c in ("red", "green", "blue"))
    assert np.all(red[cols < 20] == 255) and np.all(green[cols < 20] == 0)
    assert np.all(red[cols >= 20] == 0) and np.all(green[cols >= 20] == 255) and np.all(blue == 0)
    assert np.array_equal(np.asarray(v["thermal_case"]), res.cases["thermal"][rows, cols])


def test_ply_opens_in_open3d(written):
    import open3d as o3d

    _, _, out = written
    pc = o3d.io.read_point_cloud(str(out / "pointcloud.ply"))
    pts, col = np.asarray(pc.points), np.asarray(pc.colors)
    assert pts.shape == ((R1 - R0) * (C1 - C0) - 1, 3)
    np.testing.assert_allclose(pts[:, 2], 1.0, atol=1e-6)
    assert col.shape == pts.shape and set(np.unique(col.round(6))) == {0.0, 1.0}


def test_summary_json(written):
    _, res, out = written
    s = json.loads((out / "summary.json").read_text())
    assert s["format"] == "plantreg.summary" and s["target"] == "ir" and s["target_size"] == [W, H]
    assert s["parameters"]["edge_angle_deg"] == 12.5
    assert s["inputs"]["rig"] == str(Path("/data/rig.json").resolve())
    assert set(s["versions"]) >= {"plantreg", "numpy", "opencv", "open3d"}
    assert all(s["versions"][k] for k in ("plantreg", "numpy", "opencv", "open3d"))
    assert s["timings"] == {"mesh": 0.01, "raycast": 0.02}
    assert s["stats"] == {"triangles": 1234}
    n = H * W
    th = s["cases"]["thermal"]
    assert th["P2 occluded"] == {"code": 2, "pixels": 5, "percent": round(100 * 5 / n, 3)}
    assert th["P3.1 incoming uncertain"]["pixels"] == 3 and th["P3.2 outgoing uncertain"]["pixels"] == 4
    assert th["P5 uncertain area"]["pixels"] == 24 and th["outside source"]["pixels"] == 2
    assert th["P6 background"]["pixels"] == n - 480
    assert th["P1 legitimate"]["pixels"] == 480 - 5 - 3 - 4 - 24 - 2
    assert set(s["cases"]) == {"rgb", "thermal", "hs"}
    assert s["areas"]["P4 certain object"]["pixels"] == 480 - 24 and s["areas"]["P5 uncertain object"]["pixels"] == 24
    assert s["cameras"]["hs"]["bands"] == NB and s["cameras"]["ir"]["role"] == "target"
    assert s["points"] == 479 and "summary.json" in s["files"] and "pointcloud.ply" in s["files"]
    assert s["date"].startswith("20")


def test_existing_output_is_refused_and_replaced_only_on_request(tmp_path):
    rig, res = _result()
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    with pytest.raises(InputError) as e:
        write_outputs(res, rig, None, out, what={"areas"})
    assert str(out) in str(e.value) and "not empty" in str(e.value)
    assert [p.name for p in out.iterdir()] == ["keep.txt"]
    write_outputs(res, rig, None, out, what={"areas"}, overwrite=True)
    assert sorted(p.name for p in out.iterdir()) == ["areas.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_overwrite_never_replaces_the_rig_or_recording(tmp_path):
    """An export into the folder that holds the rig file (as the GUI passes it: a str) or the
    recording is refused even with overwrite: replacing the folder would delete the inputs."""
    from plantreg_gui.core.data.recording import Recording

    rig, res = _result()
    rig_path = tmp_path / "rig.json"
    rig.save(rig_path)
    with pytest.raises(InputError, match="would replace an input"):
        write_outputs(res, rig, None, tmp_path, what={"areas"}, overwrite=True, inputs={"rig": str(rig_path)})
    rec_dir = tmp_path / "rec"
    rec_dir.mkdir()
    (rec_dir / "recording.json").write_text("{}")
    rec = Recording(rec_dir, None, {})
    with pytest.raises(InputError, match="would replace an input"):
        write_outputs(res, rig, rec, rec_dir, what={"areas"}, overwrite=True)
    assert rig_path.is_file() and (rec_dir / "recording.json").is_file()
    write_outputs(res, rig, rec, rec_dir / "out", what={"areas"}, inputs={"rig": str(rig_path)})  # inside: fine
    assert (rec_dir / "out" / "areas.png").is_file()


def test_subset_of_outputs(tmp_path):
    rig, res = _result()
    out = write_outputs(res, rig, None, tmp_path / "o", what={"cases", "summary"})
    files = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
    assert files == ["cases/hs.png", "cases/rgb.png", "cases/thermal.png", "summary.json"]
    with pytest.raises(ValueError):
        write_outputs(res, rig, None, tmp_path / "p", what={"nonsense"})
    assert set(OUTPUTS) >= {"registered", "previews", "cases", "areas", "pointcloud", "mosaic", "summary"}


def test_cancel_mid_write_leaves_nothing(tmp_path):
    rig, res = _result()
    token = CancelToken()
    messages = []

    def cb(f, msg):
        messages.append(msg)
        if len(messages) == 6:   # after a few files are written
            token.cancel()

    out = tmp_path / "out"
    with pytest.raises(Cancelled):
        write_outputs(res, rig, None, out, progress=Reporter(cb, token))
    assert len(messages) == 6 and not out.exists()
    assert list(tmp_path.iterdir()) == []


def test_failure_mid_write_leaves_nothing(tmp_path, monkeypatch):
    rig, res = _result()

    def broken(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(export, "write_ply", broken)
    out = tmp_path / "out"
    with pytest.raises(OSError):
        write_outputs(res, rig, None, out)
    assert not out.exists() and list(tmp_path.iterdir()) == []
    # an old complete folder survives a failed overwrite untouched
    out.mkdir()
    (out / "summary.json").write_text("{}")
    with pytest.raises(OSError):
        write_outputs(res, rig, None, out, overwrite=True)
    assert [p.name for p in out.iterdir()] == ["summary.json"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_registered_tiffs_written_in_the_background_fail_and_finish_cleanly(tmp_path, monkeypatch):
    """The registered TIFFs are encoded in a background thread: a failure there (disk full) is
    raised and leaves nothing; a failure here while a TIFF is still being written waits for it,
    so that no file appears in (or re-creates) the removed folder afterwards."""
    import threading
    import time

    rig, res = _result()
    real = tiffs.write_tiff_tiled

    def full(path, *a, **k):
        if "hs" in Path(path).name:
            raise OSError(28, "No space left on device", str(path))
        return real(path, *a, **k)

    monkeypatch.setattr(tiffs, "write_tiff_tiled", full)
    out = tmp_path / "out"
    with pytest.raises(OSError) as e:
        write_outputs(res, rig, None, out)
    assert e.value.errno == 28 and not out.exists() and list(tmp_path.iterdir()) == []

    def slow(path, *a, **k):
        time.sleep(0.3)
        return real(path, *a, **k)

    def broken(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(tiffs, "write_tiff_tiled", slow)
    monkeypatch.setattr(export, "write_ply", broken)
    with pytest.raises(OSError):
        write_outputs(res, rig, None, out)
    assert not any(t.name.startswith("plantreg-write") for t in threading.enumerate())
    time.sleep(0.5)
    assert list(tmp_path.iterdir()) == []


def test_progress_reaches_one_and_is_monotonic(tmp_path):
    rig, res = _result()
    fr = []
    write_outputs(res, rig, None, tmp_path / "o", progress=Reporter(lambda f, m: fr.append(f)))
    assert fr[-1] == 1.0 and all(b >= a - 1e-9 for a, b in zip(fr, fr[1:]))
    assert os.listdir(tmp_path) == ["o"]


def test_output_has_ordinary_permissions(tmp_path):
    rig, res = _result()
    old = os.umask(0o022)
    try:
        out = write_outputs(res, rig, None, tmp_path / "o", what={"areas", "cases", "summary"})
    finally:
        os.umask(old)
    assert out.stat().st_mode & 0o777 == 0o755
    assert (out / "cases").stat().st_mode & 0o777 == 0o755
    assert (out / "areas.png").stat().st_mode & 0o777 == 0o644
    assert (out / "cases/rgb.png").stat().st_mode & 0o777 == 0o644


def test_ply_property_names_are_sanitised_and_unique():
    _, res = _result()
    res.registered = {"thermal-2": res.registered["thermal"], "x": res.registered["ir"],
                      "3d": res.registered["thermal"], "rgb": res.registered["rgb"]}
    names = export.ply_property_names(res)
    assert names == {"thermal-2": ["thermal_2"], "x": ["x_value"], "3d": ["c3d"],
                     "rgb": ["rgb_b000", "rgb_b001", "rgb_b002"]}


def test_cameras_with_clashing_file_names_are_refused(tmp_path):
    """'thermal 1' and 'thermal_1' would both be written as registered/thermal_1.tif."""
    from plantreg_gui.core.errors import InputError

    rig, res = _result()
    rig.camera("hs").name = "thermal 1"
    rig.camera("thermal").name = "thermal_1"
    res.registered = {"ir": res.registered["ir"], "thermal_1": res.registered["thermal"],
                      "thermal 1": res.registered["hs"]}
    res.cases = {"thermal_1": res.cases["thermal"], "thermal 1": res.cases["hs"]}
    with pytest.raises(InputError, match="same file registered/thermal_1.tif: .*camera 'thermal_1' and .*camera 'thermal 1'"):
        export.write_outputs(res, rig, None, tmp_path / "out")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("bands", [1, 3, 204])
def test_hit_tiles_answer_every_block_as_the_dense_image(bands, tmp_path):
    """The TIFF writer's blocks of a HitImage (occupancy grid + block) are the dense image's
    blocks, None exactly where the block holds no hit -- aligned tiles and any other block;
    the written TIFF decodes to the dense image."""
    from plantreg_gui.core.registration.hits import HitImage

    rng = np.random.default_rng(bands)
    H, W = 203, 317
    dense = np.full((H, W, bands), np.nan, np.float32)
    blob = np.zeros((H, W), bool)
    blob[40:90, 100:180] = True
    blob[rng.integers(0, H, 30), rng.integers(0, W, 30)] = True  # scattered single hits
    dense[blob] = rng.normal(size=(int(blob.sum()), bands)).astype(np.float32)
    idx = np.flatnonzero(blob)
    img = HitImage(idx, dense.reshape(-1, bands)[idx], (H, W, bands) if bands > 1 else (H, W))
    ref = dense if bands > 1 else dense[:, :, 0]
    tile_of = tiffs._hit_tiles(img)
    edge = tiffs.tiff_tile_edge(bands, 4)
    blocks = [(r, min(H, r + edge), c, min(W, c + edge)) for r in range(0, H, edge) for c in range(0, W, edge)]
    blocks += [tuple(sorted(rng.integers(0, H, 2)) + sorted(rng.integers(0, W, 2))) for _ in range(300)]
    for r0, r1, c0, c1 in blocks:
        if r1 <= r0 or c1 <= c0:
            continue
        got, want = tile_of(r0, r1, c0, c1), ref[r0:r1, c0:c1]
        if np.isnan(want).all():
            assert got is None
        else:
            assert np.array_equal(got, want, equal_nan=True)
    tiffs.write_registered_tiff(tmp_path / "h.tif", img, "deflate-fp")
    assert np.array_equal(tifffile.imread(tmp_path / "h.tif"), ref, equal_nan=True)
