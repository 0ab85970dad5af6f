"""After the two-stage fit (``fit_and_check.sh``): keep stage 1's provenance in the shipped rig
(``"calibration"."stage1"``: the hyperspectral fit of the infrared lens and the hyperspectral pose;
the top-level ``"calibration"`` is stage 2, the thermal fit, with stage 1's per-camera figures
merged in so that it reads like one fit of both cameras) and add the hand-written
``"calibration_notes"`` of ``rig_notes.json`` (what the figures mean; README, "Fit").

  python rig_provenance.py STAGE1_RIG.json RIG.json
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def merge(top: dict, first: dict) -> None:
    """Stage 1's per-camera figures into the top-level record, so that it reads like one fit of
    both cameras (``core/mixed.py`` takes each camera's ``per_camera`` median as its registration
    uncertainty): per camera / per recording / leave-one-out entries stage 2 lacks, the residual
    rows, the infrared's change, the counts and the free items."""
    for key in ("per_camera", "changes"):
        for cam, v in first.get(key, {}).items():
            if cam not in top.get(key, {}) or (key == "changes" and cam == "ir"):
                top.setdefault(key, {})[cam] = v
    for rec, cams in first.get("per_recording", {}).items():
        for cam, v in cams.items():
            top.setdefault("per_recording", {}).setdefault(rec, {}).setdefault(cam, v)
    loo, loo1 = top.setdefault("leave_one_out", {}), first.get("leave_one_out", {})
    for rec, v in loo.get("per_recording", {}).items():  # stage 2 fits the thermal camera only
        if isinstance(v.get("unavailable"), str):
            loo["per_recording"][rec] = {"thermal": {"unavailable": v["unavailable"].removeprefix("thermal: ")}}
    for cam, v in loo1.get("per_camera", {}).items():
        loo.setdefault("per_camera", {}).setdefault(cam, v)
    for rec, cams in loo1.get("per_recording", {}).items():
        for cam, v in cams.items():
            loo.setdefault("per_recording", {}).setdefault(rec, {}).setdefault(cam, v)
    top["residuals"] = sorted(top.get("residuals", []) + first.get("residuals", []), key=lambda d: -d["residual_px"])
    for key in ("landmarks_used", "observations_used"):
        top[key] = top.get(key, 0) + first.get(key, 0)
    top["free"] = sorted(set(top.get("free", [])) | set(first.get("free", [])))
    top["fitted_cameras"] = sorted(set(top.get("fitted_cameras", [])) | set(first.get("fitted_cameras", [])))
    top["command"] = first.get("command", "") + " && " + top.get("command", "")


def short_keys(x):
    """Recording names as in ``landmarks.json`` ("recordings/<plant>"), not relative to the
    per-camera landmark files the stages read."""
    if isinstance(x, dict):
        return {(k[k.rindex("recordings/"):] if isinstance(k, str) and "recordings/" in k else k): short_keys(v)
                for k, v in x.items()}
    if isinstance(x, list):
        return [short_keys(v) for v in x]
    if isinstance(x, str):
        return re.sub(r"(\.\./)+\S*?/(recordings/)", r"\2", x)
    return x


def reindex(cal: dict, stage1: bool) -> None:
    """Landmark indices as in ``landmarks.json`` (the stages number the points of their own
    per-camera file): residual rows and rejected landmarks."""
    doc = json.loads((HERE.parent / "landmarks.json").read_text())
    where = {}  # (recording, camera, k-th point of that camera) -> index in landmarks.json
    for rec, r in doc["recordings"].items():
        count: dict[str, int] = {}
        for i, pt in enumerate(r["points"]):
            for c in pt["cameras"]:
                where[(rec, c, count.get(c, 0))] = i
                count[c] = count.get(c, 0) + 1
    for d in cal.get("residuals", []):
        d["index"] = where[(d["recording"], d["camera"], d["index"])]
    cam = "hyperspectral" if stage1 else "thermal"
    for d in cal.get("landmarks_rejected", []):
        d["index"] = where[(d["recording"], cam, d["index"])]
    cal["warnings"] = [re.sub(r"landmark (\d+) of (recordings/\S+)",
                              lambda m: f"landmark {where[(m.group(2), cam, int(m.group(1)))]} of {m.group(2)}", w)
                       for w in cal.get("warnings", [])]


def main() -> None:
    stage1 = json.loads(Path(sys.argv[1]).read_text())
    path = Path(sys.argv[2])
    rig = json.loads(path.read_text())
    merge(rig["calibration"], stage1["calibration"])
    rig["calibration"] = short_keys(rig["calibration"])
    rig["calibration"]["landmarks_source"] = str((HERE.parent / "landmarks.json").resolve())
    rig["calibration"]["stages"] = ("two stages: 1. hyperspectral landmarks -> infrared k1 + hyperspectral pose "
                                    "('stage1' below); 2. thermal landmarks -> thermal pose + k1, infrared fixed "
                                    "(this entry)")
    rig["calibration"]["stage1"] = short_keys(stage1["calibration"])
    reindex(rig["calibration"], stage1=False)
    reindex(rig["calibration"]["stage1"], stage1=True)
    rig["calibration_notes"] = json.loads((HERE / "rig_notes.json").read_text())
    path.write_text(json.dumps(rig, indent=2) + "\n")
    print(f"{path}: stage 1 provenance and calibration_notes added")


if __name__ == "__main__":
    main()
