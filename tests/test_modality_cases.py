"""The modality registry and the case/area codes: one vocabulary, applied when rigs and sessions load."""

from __future__ import annotations

import json

import numpy as np
import pytest

from plantreg_gui.core.display import display
from plantreg_gui.core.camera import modality
from plantreg_gui.core.registration.cases import AREA_COLOURS, AREA_NAMES, CASE_COLOURS, CASE_NAMES, Area, Case


@pytest.mark.parametrize("spelling, canonical", [
    ("visible", "rgb"), ("Colour", "rgb"), ("color", "rgb"), ("RGB", "rgb"),
    ("lwir", "thermal"), ("IR-thermal", "thermal"), ("ir_thermal", "thermal"), ("thermal", "thermal"),
    ("nir", "infrared"), ("infrared", "infrared"), ("ir", "infrared"),
    ("hsi", "hyperspectral"), ("hyperspectral", "hyperspectral"), ("depth", "depth"),
])
def test_aliases_resolve_to_one_name(spelling, canonical):
    assert modality.canonical(spelling) == canonical


def test_registry_properties():
    assert modality.get("lwir").inverted_board and not modality.get("visible").inverted_board
    assert modality.get("lwir").unit == "°C" and modality.get("depth").unit == "mm"
    assert modality.get("visible").is_colour and modality.get("hsi").is_cube
    assert modality.get("visible").channels == 3
    assert modality.canonical("some new sensor") == "some-new-sensor"  # unknown: kept, neutral
    assert modality.get("some new sensor").cmap == "gray" and not modality.get("x").inverted_board


def test_rig_from_wizard_with_visible_and_lwir_is_rgb_and_thermal(tmp_path):
    """The real bug: a 'visible' camera was not RGB (PCA false colour, no PLY colour) and an 'lwir'
    camera was drawn as thermal but detected with normal polarity."""
    from plantreg_gui.core.calibration.detect import detect_image
    from plantreg_gui.core.calibration.board import Board
    from plantreg_gui.core.camera.rig import Rig

    cams = [{"name": "c", "modality": "visible", "width": 8, "height": 6,
             "K": [[10, 0, 4], [0, 10, 3], [0, 0, 1]]},
            {"name": "t", "modality": "LWIR", "width": 8, "height": 6,
             "K": [[10, 0, 4], [0, 10, 3], [0, 0, 1]]}]
    p = tmp_path / "rig.json"
    p.write_text(json.dumps({"cameras": cams}))
    rig = Rig.load(p)
    assert [c.modality for c in rig.cameras] == ["rgb", "thermal"]
    # a float RGB image of a 'visible' camera keeps its hues (RGB, not PCA false colour)
    img = np.zeros((6, 8, 3), np.float32)
    img[..., 0] = 1.0  # pure red
    out = display.to_rgb8(img, modality="visible")
    assert (out[..., 0] > 200).all() and (out[..., 1] < 30).all() and (out[..., 2] < 30).all()
    # detection polarity defaults by modality: 'lwir' is a thermal camera, so inverted
    board = Board("chessboard", 5, 4, 0.03)
    assert detect_image(np.zeros((60, 80), np.uint8), board, modality="lwir").inverted is True
    assert detect_image(np.zeros((60, 80), np.uint8), board, modality="visible").inverted is False


def test_session_default_polarity_by_alias(tmp_path):
    from plantreg_gui.core.calibration.board import Board
    from plantreg_gui.core.calibration.session import Session

    board = Board("chessboard", 5, 4, 0.03)
    s = Session.create(tmp_path / "s", board, {"a": "lwir", "b": "visible"})
    assert s.cameras == {"a": "thermal", "b": "rgb"}
    assert s.default_inverted("a") and not s.default_inverted("b")


def test_case_codes_keep_their_values():
    assert [int(c) for c in Case] == [0, 1, 2, 3, 4, 5, 6] and [int(a) for a in Area] == [4, 5, 6]
    assert CASE_NAMES[3] == "P3.1 incoming uncertain"
    assert AREA_NAMES[4] == "P4 certain object"
    assert Case.P2.short == "P2" and Case.P2.colour == (0, 255, 255) and Case.P1.colour is None
    assert display.CASE_COLOURS == CASE_COLOURS and display.AREA_COLOURS == AREA_COLOURS
    assert 1 not in CASE_COLOURS and 0 not in CASE_COLOURS  # P1 and background have no overlay


def test_one_depth_conversion_and_back_projection():
    from plantreg_gui.core.camera.camera import Camera
    from plantreg_gui.core.geometry.depth import back_project, to_metres, to_millimetres

    raw = np.array([[0, 1000], [2500, 65535]], np.uint16)
    m = to_metres(raw, 0.001)
    assert np.isnan(m[0, 0]) and m[0, 1] == pytest.approx(1.0) and m[1, 0] == pytest.approx(2.5)
    assert to_millimetres(raw, 0.001)[1, 0] == pytest.approx(2500.0)
    K = np.array([[100.0, 0, 1.5], [0, 100.0, 0.5], [0, 0, 1]])
    cam = Camera("d", "depth", 4, 2, K, np.zeros(5), np.eye(3), np.zeros(3))
    z = np.full((2, 4), 2.0, np.float32)
    P = back_project(cam, z)
    # pixel (row 1, col 3): x = (3 - 1.5) / 100 * 2, y = (1 - 0.5) / 100 * 2
    np.testing.assert_allclose(P[1, 3], [0.03, 0.01, 2.0], atol=1e-6)
