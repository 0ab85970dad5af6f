"""Session 13 eye readings (pixel centres at integers; u = column, v = row), infrared-thermal, read without any
rig's prediction in view. inward: unit-ish infrared direction into the leaf (for the step onto valid depth)."""
R = {
 "04philodendron/upper_right_leaf_tip_over_ground": {
     # the tip of the leaf that ends over the ground at infrared (412, 307) (depth 0.673-0.687 m on the leaf,
     # 1.24-1.26 m around the tip; the lower-right leaf, 0.69-0.70 m, lies 3-5 px further down-left); thermal: the
     # cold leaf's wedge ending against the warmer ground near the thermal image's bottom edge (v ~460 of 480)
     "r1": {"ir": [412.0, 307.5], "thermal": [170.5, 460.0]},   # infrared crop half 20 zoom 11 at (405, 300); thermal
                                                                # crops half 40 zoom 7 at (195, 439) and half 16 zoom 13
     "r2": {"ir": [411.5, 308.5], "thermal": [171.0, 459.5]},   # fresh crops: infrared half 11 zoom 15 at (406, 313);
                                                                # thermal half 22 zoom 10 at (180, 452)
     "inward": [-0.4, -0.92]},
}

NAV = ("Candidates: s13_candidates.py (convex tips of the infrared plant mask in the thermal field's border zones at "
       "0.55-0.9 m; infrared and depth only). Crops: s13_views.py panel / crop (annotate_view.crop_view; infrared "
       "zoom 9-15, thermal zoom 5-13, kept inside the image so the per-crop stretch sees no padding; no marks); the "
       "thermal crop centred by an affine guess from two s11c readings (s13_views.guess_thermal, ~10-20 px off, "
       "half-width 40-50 px) and then by the thermal image's own structure. No rig was loaded and no rig's "
       "prediction was drawn. The second reading on fresh crops (other centre, zoom and half-width).")
REJECTED = {
 "04philodendron": "V between the left and the top-middle leaves at infrared (198, 123) (two leaves at different depths: "
                   "a crossing); the front leaf's corner over the dark bottom leaf at (333, 366) (crossing); the right "
                   "leaf's rounded corners; its upper-margin notch (349, 153) not read (mid-field, not an edge point)",
 "02leopard_lily": "(372, 241) a leaf over a lower leaf (crossing in the depth map); (200, 275) and (222, 201): gaps "
                   "between two leaves; thermal there too noisy for a point",
 "03areca_palm": "(396, 254): crossing leaflets (depth map)",
 "05boston_fern": "(221, 353), (371, 110): ragged pinnae, no single point in the depth map or the infrared",
 "06weeping_fig": "(193, 303), (366, 387): gaps between leaves; the oval leaf at thermal (250, 160): its tip not found "
                  "in the infrared among the overlapping leaves, and its warm spots are reflections (move with the "
                  "viewpoint)",
 "01grapevine": "(367, 262): a lobed margin with a gap; the top leaf's top-right corner (361, 143): rounded in both "
                "images (a 3-5 px choice along the curve)",
}
