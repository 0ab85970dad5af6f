"""How the other camera's inward step (finalize.py) moves the thermal figures (issue 23, item 6).

finalize.py moves a pair's infrared point inward onto valid depth and the other camera's point by
the same physical distance, taken as x1.8 (hyperspectral) / x2.2 (thermal) pixels per infrared
pixel along the other image's OWN inward direction. The rig's local mapping says otherwise
(``scales``: 1.64-1.92 hyperspectral, 1.81-2.16 thermal, smallest near the image centre where the
depth lens is least barrel-distorted). Variants written as landmark files (all pairs of
``annotations.json``, fitted and held out, in one file for ``thermal_eval.py compare``):

* ``shipped``: as finalize.py wrote them;
* ``mapped``: the other point moved by J @ (infrared step), J = d(other pixel) / d(infrared pixel) of
  RIG at the stepped point's depth (the step's image, not a guessed scale and direction);

  cd resources/plant3dimagereg/landmark_scripts && PYTHONPATH=../../.. python step_variants.py scales [RIG]
  cd resources/plant3dimagereg/landmark_scripts && PYTHONPATH=../../.. python step_variants.py write OUTDIR [RIG]
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from annotate_view import load
from plantreg_gui.core.camera.rig import Rig
from plantreg_gui.core.rigfit.rigfit import landmark_depth

HERE = Path(__file__).resolve().parent


def jacobian(rig: Rig, cam: str, uv: np.ndarray, z: float) -> np.ndarray:
    """(2, 2) d(other pixel) / d(infrared pixel) of ``rig`` at infrared pixel ``uv`` (2,) and depth ``z``."""
    dc = rig.depth()

    def proj(p: np.ndarray) -> np.ndarray:
        xy = dc.undistort_normalized(np.asarray(p, float)[None])
        return rig.camera(cam).project(dc.to_rig(np.concatenate([xy, [[1.0]]], 1) * z))[0][0]

    p0 = proj(uv)
    return np.stack([proj(uv + np.array([0.5, 0.0])) - p0, proj(uv + np.array([0.0, 0.5])) - p0], axis=1) / 0.5


def items(rig: Rig):
    ann = json.loads((HERE / "annotations.json").read_text())
    depth: dict[str, np.ndarray] = {}
    for key in sorted(ann):
        plant, cam = key.split("/")
        d = depth.setdefault(plant, load(plant, "depth") / 1000.0)
        for it in ann[key]:
            z, _ = landmark_depth(d, np.asarray(it["ir"], float))
            yield plant, cam, it, z, jacobian(rig, cam, np.asarray(it["ir"], float), z)


def scales(rig: Rig) -> None:
    print(f"{'pair':60s} {'z m':>6s} {'step ir':>7s} {'local':>6s} {'along':>6s} {'used':>5s} {'|mapped-used| px':>8s}")
    for plant, cam, it, z, J in items(rig):
        s_ir = np.subtract(it["ir"], it["feature_ir"])
        s_o = np.subtract(it["other"], it["feature_other"])
        n = float(np.linalg.norm(s_ir))
        along = np.linalg.norm(J @ s_ir) / n if n else float("nan")
        used = np.linalg.norm(s_o) / n if n else float("nan")
        print(f"{plant + '/' + cam + ' ' + it['note'][:40]:60s} {z:6.3f} {n:7.1f} {np.sqrt(abs(np.linalg.det(J))):6.2f} "
              f"{along:6.2f} {used:5.2f} {np.linalg.norm(J @ s_ir - s_o):8.2f}")


def write(out: Path, rig: Rig) -> None:
    out.mkdir(parents=True, exist_ok=True)
    docs = {v: {"format": "plantreg.landmarks", "version": 1, "recordings": {}} for v in ("shipped", "mapped")}
    for plant, cam, it, z, J in items(rig):
        fi, fo = np.asarray(it["feature_ir"], float), np.asarray(it["feature_other"], float)
        pi = np.asarray(it["ir"], float)
        var = {"shipped": (it["ir"], it["other"]), "mapped": (it["ir"], (fo + J @ (pi - fi)).tolist())}
        for v, (a, b) in var.items():
            pts = docs[v]["recordings"].setdefault(f"{HERE.parent.resolve()}/recordings/{plant}", {"points": []})["points"]
            pts.append({"depth_uv": [round(float(x), 2) for x in a], "cameras": {cam: [round(float(x), 2) for x in b]},
                        "note": it.get("note", "") + (" [held out]" if it.get("held_out") else "")})
    for v, doc in docs.items():
        if doc["recordings"]:
            (out / f"{v}.json").write_text(json.dumps(doc, indent=1) + "\n")
            print(out / f"{v}.json")


if __name__ == "__main__":
    rig = Rig.load(sys.argv[3] if sys.argv[1] == "write" and len(sys.argv) > 3 else
                   sys.argv[2] if sys.argv[1] == "scales" and len(sys.argv) > 2 else HERE.parent / "rig.json")
    scales(rig) if sys.argv[1] == "scales" else write(Path(sys.argv[2]), rig)
