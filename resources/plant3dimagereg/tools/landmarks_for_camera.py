"""The landmarks of one camera, as a landmarks file of their own (for the two-stage fit in
``fit_and_check.sh``: the hyperspectral landmarks fit the infrared lens and the hyperspectral pose,
then the thermal landmarks fit the thermal camera with the infrared held fixed).

  python landmarks_for_camera.py CAMERA OUT.json   (recording paths rewritten relative to OUT.json)
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

RES = Path(__file__).resolve().parent.parent


def main() -> None:
    cam, out = sys.argv[1], Path(sys.argv[2]).resolve()
    doc = json.loads((RES / "landmarks.json").read_text())
    recs = {}
    for key, r in doc["recordings"].items():
        pts = [{**p, "cameras": {cam: p["cameras"][cam]}} for p in r["points"] if cam in p["cameras"]]
        if pts:
            recs[os.path.relpath(RES / key, out.parent)] = {"points": pts}
    if not recs:
        raise SystemExit(f"{RES / 'landmarks.json'}: no landmarks of camera '{cam}'")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({**doc, "recordings": recs}, indent=1) + "\n")
    print(f"{out}: {sum(len(r['points']) for r in recs.values())} {cam} landmarks in {len(recs)} recordings")


if __name__ == "__main__":
    main()
