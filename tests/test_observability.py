"""The observability bound of P1 coverage (``synthetic.render.observable_views``), checked against an
analytic scene: a thin bar over a floor, whose hidden space a source camera looks through."""

import numpy as np

from plantreg_gui.core.synthetic import MAT_GROUND, MAT_SOIL, MAT_STEM, Scene, demo_rig, ground_truth
from plantreg_gui.core.synthetic.render import observable_views

BAR_Z, FLOOR_Z, HALF_W, HALF_L = 0.6, 1.0, 0.003, 0.1


def _bar_scene() -> Scene:
    """Floor (object) at z = 1 m, a bar 6 mm wide and 20 cm long along y at z = 0.6 m, ground at 1.2 m."""
    quads = [(MAT_GROUND, 1.2, 5.0, 5.0), (MAT_SOIL, FLOOR_Z, 0.12, 0.14), (MAT_STEM, BAR_Z, HALF_W, HALF_L)]
    V, T, M = [], [], []
    for mat, z, hx, hy in quads:
        n = len(V) * 4
        V.append(np.array([[-hx, -hy, z], [hx, -hy, z], [hx, hy, z], [-hx, hy, z]]))
        T.append(np.array([[0, 1, 2], [0, 2, 3]]) + n)
        M.append(np.full(2, mat))
    V = np.concatenate(V)
    normals = np.tile([0.0, 0.0, -1.0], (len(V), 1))
    return Scene(V, np.concatenate(T), np.concatenate(M).astype(np.int32), np.zeros((len(V), 2)), normals,
                 1.2, [], 0)


def test_views_through_the_hidden_space_under_a_bar_are_not_observable():
    rig = demo_rig()
    scene = _bar_scene()
    gt = ground_truth(rig, scene, "ir", sources=["thermal"])
    obs = observable_views(rig, scene, gt)["thermal"]
    match = gt.matchable["thermal"] & (gt.material == MAT_SOIL)
    # analytic: the segment from the floor point to the thermal camera passes through the bar's shadow
    # (the space behind the bar along the depth camera's rays, the camera at the origin)
    X = gt.points_rig[match]
    S = rig.camera("thermal").center_rig
    hidden = np.zeros(len(X), dtype=bool)
    for z in np.arange(BAR_Z + 1e-4, FLOOR_Z - 0.002, 1e-4):
        P = X + (X[:, 2:3] - z) / (X[:, 2:3] - S[2]) * (S - X)  # the segment's point at depth z
        hidden |= (np.abs(P[:, 0] / P[:, 2] * BAR_Z) <= HALF_W) & (np.abs(P[:, 1] / P[:, 2] * BAR_Z) <= HALF_L)
    assert hidden.sum() > 2000  # a band ~4.7 cm wide: the source sees under the bar from 12 cm aside
    got_hidden = ~obs[match]
    # the same pixels, up to the border of the band (where the lookup and the step decide)
    assert (got_hidden != hidden).sum() <= 0.02 * hidden.sum(), ((got_hidden != hidden).sum(), hidden.sum())
    assert not obs[~gt.matchable["thermal"]].any()
