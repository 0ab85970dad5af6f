"""The one pipeline (core/pipeline/pipeline.py) and the parameters' one table of ranges
(RegistrationParams.validate): what the command line, batch and the GUI's export share."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import tifffile

from plantreg_gui.core.errors import InputError
from plantreg_gui.core.pipeline import batch
from plantreg_gui.core.pipeline.pipeline import OutputOptions, export, without_mixed
from plantreg_gui.core.registration.hits import HitImage
from plantreg_gui.core.registration.params import LIMITS, RegistrationParams

from test_export import _result  # a hand-made result with known content


@pytest.mark.parametrize("field, bad, words", [
    ("edge_angle_deg", 95.0, "--edge-angle must be from 0.5 to 89.5 degrees, got 95"),
    ("edge_angle_deg", 0.0, "--edge-angle"),
    ("flying_jump_rel", 0.0, "--flying-jump must be between 0 and 1"),
    ("denoise_size", 4, "--denoise-size must be an odd number from 3 to 15"),
    ("mixed_radius_px", 51.0, "--mixed-radius"),
    ("occlusion_tol_m", 0.2, "occlusion_tol_m must be from 0 to 50 mm, got 200"),
    ("edge_angle_deg", float("nan"), "--edge-angle"),
])
def test_validate_names_the_parameter_out_of_range(field, bad, words):
    from plantreg_gui.cli.register_cmd import OPTION_NAMES

    p = RegistrationParams(**{field: bad})
    with pytest.raises(InputError) as e:
        p.validate(OPTION_NAMES)
    assert words in str(e.value)
    assert RegistrationParams().validate() is not None  # the defaults are in range


def test_gui_spin_boxes_take_their_ranges_from_the_table():
    """The GUI's parameter panel reads LIMITS (it had 0.5-89 degrees where the CLI had 0-90)."""
    import ast

    src = (Path(__file__).resolve().parents[1] / "plantreg_gui/gui/registration/params_panel.py").read_text()
    numbers = [n.value for n in ast.walk(ast.parse(src)) if isinstance(n, ast.Constant)
               and isinstance(n.value, float) and n.value not in (1000.0,)]
    assert not numbers, f"ranges written in the panel: {numbers}"
    assert LIMITS["edge_angle_deg"].contains(15.0) and not LIMITS["edge_angle_deg"].contains(90.0)


def test_drop_mixed_in_an_export_leaves_the_shown_result_alone(tmp_path):
    rig, res = _result()
    flagged = np.zeros(res.shape, bool)
    flagged[12, 10:20] = True
    res.mixed = {"thermal": flagged, "hs": flagged}
    dense = res.registered["hs"]  # the cube kept at its hits, as big results are
    idx = np.flatnonzero(np.isfinite(dense[..., 0]).ravel())
    res.registered["hs"] = HitImage(idx, dense.reshape(-1, dense.shape[2])[idx].copy(), dense.shape)
    before = {c: np.array(np.asarray(v), copy=True) for c, v in res.registered.items()}
    out = export(res, rig, None, tmp_path / "out", OutputOptions(parts=("registered",), drop_mixed=True))
    th = tifffile.imread(out / "registered" / "thermal.tif")
    assert np.isnan(th[flagged]).all()
    keep = ~flagged & np.isfinite(before["thermal"])
    np.testing.assert_array_equal(th[keep], before["thermal"][keep])
    for c, v in res.registered.items():  # what the GUI shows is unchanged
        np.testing.assert_array_equal(np.asarray(v), before[c])
    dropped = without_mixed(res)
    assert np.isnan(np.asarray(dropped.registered["hs"])[flagged]).all()
    assert dropped.registered["ir"] is res.registered["ir"]  # no copy of what has no flag


def test_batch_has_drop_mixed(demo_dir, tmp_path):
    """plantreg batch --drop-mixed (it existed only in plantreg register): NaN exactly where the
    job's own cases/<camera>_edge.png flags a pixel; the flag enters the resume hash."""
    s = batch.BatchSettings(rig=str(demo_dir / "rig.json"), target="ir", out=str(tmp_path / "out"),
                            params=RegistrationParams().to_dict(), outputs=("registered", "edges", "summary"),
                            drop_mixed=True)
    job = batch.plan([demo_dir / "recording"], s.out)[0]
    row = batch.run_job(s, job)
    assert row["status"] == "done", row
    out = Path(row["out"])
    import cv2

    n = 0
    for edge in (out / "cases").glob("*_edge.png"):
        cam = edge.name[: -len("_edge.png")]
        m = cv2.imread(str(edge), cv2.IMREAD_UNCHANGED) == 255
        img = tifffile.imread(out / "registered" / f"{cam}.tif")
        flagged = m if img.ndim == 2 else m[..., None].repeat(img.shape[2], axis=2)
        assert np.isnan(img[flagged]).all(), cam
        n += int(m.sum())
    assert n > 0  # the demo has mixed pixels to drop
    plain = batch.BatchSettings(**{**s.__dict__, "drop_mixed": False})
    assert batch.job_hash(plain, job.recording) != batch.job_hash(s, job.recording)
