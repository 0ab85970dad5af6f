# raw eye readings (pixel centres at integers). inward: unit-ish IR direction into the leaf (for the depth step)
R = {
 "04philodendron/top_left_leaf_apex": {"r1": {"ir": [237.0, 79.0], "thermal": [619.0, 104.5]},
                                       "r2": {"ir": [237.5, 78.5], "thermal": [619.5, 105.0]}, "inward": [0.3, 1.0]},
 "04philodendron/top_right_leaf_lower_right_corner": {"r1": {"ir": [385.0, 222.5], "thermal": [355.0, 424.0]},
                                       "r2": {"ir": [385.0, 222.5], "thermal": [354.0, 422.5]}, "inward": [-0.7, -0.7]},
 "02leopard_lily/top_leaf_tip": {"r1": {"ir": [287.5, 128.5], "thermal": [561.0, 229.0]},
                                 "r2": {"ir": [288.0, 128.0], "thermal": [557.5, 228.5]}, "inward": [0.35, 0.94]},
 "01grapevine/top_leaf_notch_at_stake": {"r1": {"ir": [315.0, 148.0], "thermal": [478.0, 287.0]},
                                 "r2": {"ir": [318.5, 148.5], "thermal": None}, "inward": [0, 1]},
 "01grapevine/bottom_leaf_lowest_lobe_tip": {"r1": {"ir": [320.5, 336.0], "thermal": [108.5, 284.0]},
                                 "r2": {"ir": [321.0, 336.5], "thermal": [109.5, 279.0]}, "inward": [0, -1]},
}
R["04philodendron/bottom_dark_leaf_apex"] = {"r1": {"ir": [293.5, 400.5], "thermal": [21.0, 241.0]},
                                            "r2": {"ir": [293.0, 400.5], "thermal": [21.5, 240.0]}, "inward": [-0.2, -1.0]}
R["02leopard_lily/upper_left_leaf_tip"] = {"r1": {"ir": [221.5, 160.0], "thermal": [440.0, 88.0]},
                                          "r2": {"ir": [222.0, 159.5], "thermal": [441.5, 87.5]}, "inward": [0.5, 0.87]}
R["04philodendron/front_leaf_apex_down"] = {"r1": {"ir": [376.5, 374.5], "thermal": [45.5, 395.0]},
                                           "r2": {"ir": [376.5, 374.0], "thermal": [46.5, 389.0]}, "inward": [-0.5, -0.87]}
# infrared-hyperspectral pairs (cam "hyperspectral"; HS is turned ~90 deg anticlockwise: IR (du, dv) -> HS (dv, -du))
R["04philodendron/top_right_leaf_lower_right_corner#hs"] = {"cam": "hyperspectral",
    "r1": {"ir": [385.0, 222.5], "hyperspectral": [216.0, 148.5]}, "r2": {"ir": [385.5, 222.5], "hyperspectral": [217.0, 149.5]}, "inward": [-0.7, -0.7]}
R["04philodendron/front_leaf_apex_down#hs"] = {"cam": "hyperspectral",
    "r1": {"ir": [377.0, 374.5], "hyperspectral": [479.0, 170.0]}, "r2": {"ir": [376.5, 374.0], "hyperspectral": [480.5, 167.5]}, "inward": [-0.5, -0.87]}
R["02leopard_lily/upper_left_leaf_tip#hs"] = {"cam": "hyperspectral",
    "r1": {"ir": [221.5, 160.0], "hyperspectral": [122.5, 427.0]}, "r2": {"ir": [221.5, 160.0], "hyperspectral": [122.5, 427.5]}, "inward": [0.5, 0.87]}
R["02leopard_lily/lower_right_leaf_tip#hs"] = {"cam": "hyperspectral",
    "r1": {"ir": [438.0, 342.5], "hyperspectral": [430.5, 59.5]}, "r2": {"ir": [437.5, 342.0], "hyperspectral": [429.5, 56.5]}, "inward": [-0.9, -0.45]}
# bottom tip: readings agree (IR 0.5, HS 2.1 px) but the hyperspectral tip ends 2-3 px from the image border: not kept
R["02leopard_lily/bottom_leaf_tip#hs"] = {"cam": "hyperspectral", "drop": "hyperspectral tip 2-3 px from the image border",
    "r1": {"ir": [258.5, 396.0], "hyperspectral": [507.5, 369.5]}, "r2": {"ir": [258.5, 396.5], "hyperspectral": [509.0, 371.0]}, "inward": [0.0, -1.0]}
R["01grapevine/bottom_leaf_lowest_lobe_tip#hs"] = {"cam": "hyperspectral",
    "r1": {"ir": [321.0, 336.5], "hyperspectral": [426.0, 255.5]}, "r2": {"ir": [320.5, 336.0], "hyperspectral": [427.0, 255.0]}, "inward": [0.0, -1.0]}

NAV = ("Crops: landmark_scripts/annotate_view.crop_view (thermal pad NaN so the per-crop stretch ignores it), infrared zoom "
       "6-13, other camera zoom 3-8, no marks; the second reading on a fresh crop (other random offset, other zoom). "
       "Centring: each image's own structure (side-by-side overviews, contour_points candidates), rig_nominal.json's "
       "prediction, and an affine correction of that prediction fitted to this reader's own first kept pairs (10 px "
       "residuals; navigation only). No fitted rig was loaded and no rig's prediction was drawn.")
REJECTED = {
 "01grapevine": "top-leaf notch at the stake (IR readings 3.5 px apart: the stake's shadow makes the vertex ambiguous); lowest lobe tip thermal (5.1 px apart along the blurred rounded margin, as the README's finding 6); right-leaf margin notch and petiole sinus (no matching thermal point); thermal margins blotchy",
 "02leopard_lily": "central leaf tips (crossings; thermal at background temperature); upper-right and lower-right tips outside the thermal image; the bottom tip's hyperspectral tip 2-3 px from the image border",
 "03areca_palm": "leaflet tips proposed by contour candidates (contour_points) matched by the corrected nominal prediction: all crossings of leaflets or cut by the thermal border",
 "04philodendron": "front leaf apex thermal (readings 5.1/6.1 px apart: a blurred V); front-left leaf's lower corner, right leaf's corners, inner V-notches and a leaf gap (crossings or rounded); vein hub (not a point); the upper-right leaf's top edge",
 "05boston_fern": "frond tips at the thermal image's lower border (ragged pinnae, no single point in the thermal image)",
 "06weeping_fig": "a ring-like curled leaf near IR (262, 178) / thermal (378, 158) (no defined point at this zoom); gaps between leaves (bounded by different leaves); no leaf tip matched with confidence",
}
