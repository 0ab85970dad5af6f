"""The README's description of the demo rig matches the rig the generator builds (issue 11,
defect 18: fields of view had been called toe-in angles)."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

README = Path(__file__).resolve().parents[1] / "README.md"


def test_readme_fields_of_view_and_toe_in_are_the_demo_rigs():
    from plantreg_gui.core.synthetic import demo_rig

    text = " ".join(README.read_text(encoding="utf-8").split())
    rig = demo_rig()
    z0 = rig.depth().R_cam_rig.T @ np.array([0.0, 0.0, 1.0])
    for name in ("thermal", "hyperspectral"):
        m = re.search(name + r" \(([\d.]+)° field of view\) toed in ([\d.]+)° from ([\d.]+) cm", text)
        assert m, f"README: no field of view / toe-in sentence for {name}"
        fov, toe, off_cm = (float(g) for g in m.groups())
        cam = rig.camera(name)
        assert abs(fov - math.degrees(2 * math.atan(cam.width / 2 / cam.K[0, 0]))) < 0.1
        axis = cam.R_cam_rig.T @ np.array([0.0, 0.0, 1.0])
        assert abs(toe - math.degrees(math.acos(float(np.clip(axis @ z0, -1, 1))))) < 0.1
        assert abs(off_cm - 100 * abs(cam.center_rig[0])) < 0.1
