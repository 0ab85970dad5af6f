"""The landmarks file (core/data/landmarks.py): round trip and bad files with one clear line."""

import json

import numpy as np
import pytest

from plantreg_gui.core.errors import InputError
from plantreg_gui.core.data.landmarks import Landmark, LandmarkSet
from plantreg_gui.core.synthetic import demo_rig

ISSUE_EXAMPLE = {"format": "plantreg.landmarks", "version": 1,
                 "recordings": {"recordings/01grapevine": {"points": [
                     {"depth_uv": [412.0, 233.5], "cameras": {"thermal": [301.2, 118.0], "hyperspectral": [160.5, 202.0]},
                      "note": "leaf tip"}]}}}


def _write(tmp_path, d, name="landmarks.json"):
    p = tmp_path / name
    p.write_text(d if isinstance(d, str) else json.dumps(d))
    return p


def test_issue_example_round_trips(tmp_path):
    d = json.loads(json.dumps(ISSUE_EXAMPLE))
    d["annotator"] = "someone"                                  # unknown keys are kept
    d["recordings"]["recordings/01grapevine"]["points"][0]["uncertainty_px"] = 2.0
    d["recordings"]["recordings/01grapevine"]["plant"] = "grapevine"
    p = _write(tmp_path, d)
    ls = LandmarkSet.load(p, rig=demo_rig())
    assert ls.count() == 1 and ls.camera_names == ["hyperspectral", "thermal"]
    lm = ls.recordings["recordings/01grapevine"][0]
    assert np.array_equal(lm.depth_uv, [412.0, 233.5]) and lm.note == "leaf tip"
    assert ls.folder("recordings/01grapevine") == tmp_path / "recordings" / "01grapevine"
    ls.save(tmp_path / "again.json")
    assert json.loads((tmp_path / "again.json").read_text()) == d


def test_built_in_memory_round_trips(tmp_path):
    ls = LandmarkSet({"a": [Landmark([1.25, 2.5], {"rgb": [3.0, 4.125]}),
                            Landmark([5, 6], {}, note="depth only")], "/abs/b": []})
    ls.save(tmp_path / "l.json")
    back = LandmarkSet.load(tmp_path / "l.json")
    assert back.to_dict() == ls.to_dict()
    assert back.folder("/abs/b").as_posix() == "/abs/b"


def _broken(field_path, value):
    d = json.loads(json.dumps(ISSUE_EXAMPLE))
    obj = d
    for k in field_path[:-1]:
        obj = obj[k]
    if value is KeyError:
        del obj[field_path[-1]]
    else:
        obj[field_path[-1]] = value
    return d


PT = ("recordings", "recordings/01grapevine", "points", 0)


@pytest.mark.parametrize("content, words", [
    ("{not json", "not valid JSON"),
    ([1, 2], "top level"),
    (_broken(("format",), "plantreg.rig"), "expected 'plantreg.landmarks'"),
    (_broken(("version",), 2), "version 2"),
    (_broken(("version",), "one"), "whole number"),
    (_broken(("recordings",), KeyError), "\"recordings\" must be"),
    (_broken(PT + ("depth_uv",), KeyError), "missing \"depth_uv\""),
    (_broken(PT + ("depth_uv",), [1.0]), "two numbers"),
    (_broken(PT + ("depth_uv",), [1.0, "x"]), "two numbers"),
    ('{"format": "plantreg.landmarks", "version": 1, "recordings": {"r": {"points": '
     '[{"depth_uv": [NaN, 2], "cameras": {}}]}}}', "finite"),
    (_broken(PT + ("cameras",), {"thermal": [float("inf"), 2]}), "finite"),
    (_broken(PT + ("cameras",), [1, 2]), "\"cameras\" must be an object"),
    (_broken(PT + ("note",), 5), "note"),
    (_broken(("recordings", "recordings/01grapevine", "points"), {}), "expected {\"points\""),
])
def test_bad_files_give_one_line_naming_the_file(tmp_path, content, words):
    p = _write(tmp_path, content)
    with pytest.raises(InputError) as e:
        LandmarkSet.load(p)
    msg = str(e.value)
    assert str(p) in msg and words in msg and "\n" not in msg, msg


@pytest.mark.parametrize("cams, depth_uv, words", [
    ({"nir": [1, 2]}, [10, 10], "unknown camera 'nir'"),
    ({"ir": [1, 2]}, [10, 10], "is the depth camera"),
    ({"thermal": [700, 2]}, [10, 10], "outside camera 'thermal'"),
    ({"thermal": [7, 2]}, [-3, 10], "outside the depth camera"),
])
def test_landmarks_are_checked_against_the_rig(tmp_path, cams, depth_uv, words):
    p = _write(tmp_path, {"format": "plantreg.landmarks", "version": 1,
                          "recordings": {"r": {"points": [{"depth_uv": depth_uv, "cameras": cams}]}}})
    with pytest.raises(InputError) as e:
        LandmarkSet.load(p, rig=demo_rig())
    assert words in str(e.value) and str(p) in str(e.value)


def test_missing_recordings_are_named(tmp_path):
    p = _write(tmp_path, ISSUE_EXAMPLE)
    with pytest.raises(InputError, match="'recordings/01grapevine' does not exist"):
        LandmarkSet.load(p, check_recordings=True)
    (tmp_path / "recordings" / "01grapevine").mkdir(parents=True)
    with pytest.raises(InputError, match="no recording.json"):
        LandmarkSet.load(p, check_recordings=True)
    with pytest.raises(InputError, match="not found"):
        LandmarkSet.load(tmp_path / "nope.json")
