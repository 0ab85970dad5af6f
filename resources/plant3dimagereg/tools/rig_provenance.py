"""After the two-stage fit (``fit_and_check.sh``): keep stage 1's provenance in the shipped rig
(``"calibration"."stage1"``: the hyperspectral fit of the infrared lens and the hyperspectral pose;
the top-level ``"calibration"`` is stage 2, the thermal fit) and add the hand-written
``"calibration_notes"`` of ``rig_notes.json`` (what the figures mean; README, "Fit").

  python rig_provenance.py STAGE1_RIG.json RIG.json
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main() -> None:
    stage1 = json.loads(Path(sys.argv[1]).read_text())
    path = Path(sys.argv[2])
    rig = json.loads(path.read_text())
    rig["calibration"]["stages"] = ("two stages: 1. hyperspectral landmarks -> infrared k1 + hyperspectral pose "
                                    "('stage1' below); 2. thermal landmarks -> thermal pose + k1, infrared fixed "
                                    "(this entry)")
    rig["calibration"]["stage1"] = stage1["calibration"]
    rig["calibration_notes"] = json.loads((HERE / "rig_notes.json").read_text())
    path.write_text(json.dumps(rig, indent=2) + "\n")
    print(f"{path}: stage 1 provenance and calibration_notes added")


if __name__ == "__main__":
    main()
