"""Build ``../landmarks.json`` (plantreg.landmarks v1) from ``annotations.json``.

``annotations.json``: {"PLANT/CAMERA": [{"ir": [u, v], "other": [u, v], "note": ..., "how": ...}, ...]}
(the accepted pairs with how each was obtained). Each pair becomes one landmark point
{"depth_uv": ir, "cameras": {CAMERA: other}, "note": ...}; recording paths are relative to the
landmarks file ("recordings/01grapevine").

  python resources/plant3dimagereg/tools/build_landmarks.py
"""

from __future__ import annotations

import json
from pathlib import Path

HERE = Path(__file__).resolve().parent
OUT = HERE.parent / "landmarks.json"


def main() -> None:
    ann = json.loads((HERE / "annotations.json").read_text())
    recs: dict[str, dict] = {}
    for key in sorted(ann):
        plant, cam = key.split("/")
        pts = recs.setdefault(f"recordings/{plant}", {"points": []})["points"]
        for it in ann[key]:
            pts.append({"depth_uv": [round(float(x), 2) for x in it["ir"]],
                        "cameras": {cam: [round(float(x), 2) for x in it["other"]]},
                        "note": it.get("note", "")})
    doc = {"format": "plantreg.landmarks", "version": 1, "recordings": recs}
    OUT.write_text(json.dumps(doc, indent=1) + "\n")
    n = sum(len(r["points"]) for r in recs.values())
    print(f"{OUT}: {n} points in {len(recs)} recordings")


if __name__ == "__main__":
    main()
