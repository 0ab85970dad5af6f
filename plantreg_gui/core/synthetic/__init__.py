"""Synthetic ground truth: a demo rig placed like the paper's, a plant scene of known geometry,
rendered recordings of every modality, and the true registration of every pixel.

```python
from plantreg_gui.core.synthetic import demo_rig, make_plant_scene, render_recording, ground_truth
rig = demo_rig()                      # ir (depth), rgb, thermal, hyperspectral
scene = make_plant_scene(seed=0)      # pot, soil, stems, 8-10 curved overlapping leaves, ground
rec = render_recording(rig, scene)    # depth (mm, uint16) + one image per camera
gt = ground_truth(rig, scene, "ir")   # true points, source pixels, visibility per source
```
"""

from .demo import SIZES, demo_rig, write_demo
from .render import GroundTruth, ground_truth, render_depth, render_recording
from .scene import GROUND_Z, MAT_GROUND, MAT_LEAF0, MAT_POT, MAT_SOIL, MAT_STEM, Leaf, Scene, make_plant_scene

__all__ = [
    "GROUND_Z", "GroundTruth", "Leaf", "MAT_GROUND", "MAT_LEAF0", "MAT_POT", "MAT_SOIL", "MAT_STEM",
    "SIZES", "Scene", "demo_rig", "ground_truth", "make_plant_scene", "render_depth", "render_recording",
    "write_demo",
]
