"""Build ``../landmarks.json`` (plantreg.landmarks v1) from ``annotations.json``, and
``../landmarks_heldout.json`` from the annotations marked ``"held_out"`` (read after ``rig.json``
was fitted and kept out of its fit, to check it); each held-out point keeps its ``"held_out_kind"``
(``independent``: read without any mark of a rig's prediction, a real check; ``found_with_rig``:
located with rig.json's predictions, so it flatters that rig; README, "Session landmarks").

``annotations.json``: {"PLANT/CAMERA": [{"ir": [u, v], "other": [u, v], "note": ..., "how": ...}, ...]}
(the accepted pairs with how each was obtained). Each pair becomes one landmark point
{"depth_uv": ir, "cameras": {CAMERA: other}, "note": ...}; recording paths are relative to the
landmarks file ("recordings/01grapevine").

  python resources/plant3dimagereg/landmark_scripts/build_landmarks.py
"""

from __future__ import annotations

import json
from pathlib import Path

HERE = Path(__file__).resolve().parent
OUT = HERE.parent / "landmarks.json"
HELD = HERE.parent / "landmarks_heldout.json"  # points kept out of rig.json's fit (annotations with "held_out")


def build(held_out: bool) -> tuple[dict, int]:
    ann = json.loads((HERE / "annotations.json").read_text())
    recs: dict[str, dict] = {}
    for key in sorted(ann):
        plant, cam = key.split("/")
        for it in ann[key]:
            if bool(it.get("held_out")) != held_out:
                continue
            pts = recs.setdefault(f"recordings/{plant}", {"points": []})["points"]
            pts.append({"depth_uv": [round(float(x), 2) for x in it["ir"]],
                        "cameras": {cam: [round(float(x), 2) for x in it["other"]]},
                        "note": it.get("note", ""),
                        **({"held_out_kind": it["held_out_kind"]} if held_out else {})})
    return {"format": "plantreg.landmarks", "version": 1, "recordings": recs}, \
        sum(len(r["points"]) for r in recs.values())


def main() -> None:
    for out, held in ((OUT, False), (HELD, True)):
        doc, n = build(held)
        if held and not n:  # nothing held out: no file (a stale one would claim a check that is not there)
            out.unlink(missing_ok=True)
            print(f"{out}: no held-out points, not written")
            continue
        out.write_text(json.dumps(doc, indent=1) + "\n")
        print(f"{out}: {n} points in {len(doc['recordings'])} recordings")


if __name__ == "__main__":
    main()
