"""Placement of the landmark views' point labels (pure geometry, no Qt): labels of near points
used to be written over each other (grapevine landmarks 1/2 and 4/5) and labels of points at the
right edge were cut off, since every label sat at the same offset from its marker."""

import itertools

from plantreg_gui.gui.landmarks.labels import GAP_X, MARKER_HALF, leader_end, place_labels

VIEW = (0.0, 0.0, 450.0, 500.0)
SIZE = (62.0, 17.0)  # "5: 4.7 px" in the 9 pt bold font


def overlap(a, b):
    return min(a[2], b[2]) > max(a[0], b[0]) and min(a[3], b[3]) > max(a[1], b[1])


def inside(a, bounds=VIEW):
    return a[0] >= bounds[0] and a[1] >= bounds[1] and a[2] <= bounds[2] and a[3] <= bounds[3]


def test_a_lone_point_keeps_the_usual_place_right_above():
    (box,) = place_labels([(100.0, 200.0)], [SIZE], VIEW)
    assert box[0] == 100.0 + GAP_X and box[3] < 200.0 and box[2] - box[0] == SIZE[0]
    assert leader_end((100.0, 200.0), box) is None  # next to its point: no line needed


def test_labels_of_near_points_do_not_overlap():
    # a cluster as on the grapevine (1/2 six pixels apart, 4/5 and 7 in a row), plus a pile-up
    anchors = [(140.0, 455.0), (146.0, 461.0), (305.0, 498.0 - 20), (320.0, 497.0 - 20), (219.0, 499.0 - 20),
               (262.0, 470.0), (200.0, 100.0), (203.0, 103.0), (206.0, 106.0), (209.0, 109.0)]
    boxes = place_labels(anchors, [SIZE] * len(anchors), VIEW)
    for a, b in itertools.combinations(boxes, 2):
        assert not overlap(a, b), (a, b)
    assert all(inside(b) for b in boxes)
    # a label does not cover another point's marker
    for i, b in enumerate(boxes):
        for j, (x, y) in enumerate(anchors):
            if i != j:
                assert not overlap(b, (x - MARKER_HALF, y - MARKER_HALF, x + MARKER_HALF, y + MARKER_HALF))
    # deterministic: the same points give the same picture
    assert place_labels(anchors, [SIZE] * len(anchors), VIEW) == boxes


def test_labels_at_the_edges_flip_inside_the_view():
    (right,) = place_labels([(440.0, 250.0)], [SIZE], VIEW)
    assert inside(right) and right[2] < 440.0  # to the left of its point
    (top,) = place_labels([(100.0, 4.0)], [SIZE], VIEW)
    assert inside(top) and top[1] > 4.0  # below its point
    (corner,) = place_labels([(445.0, 3.0)], [SIZE], VIEW)
    assert inside(corner) and corner[2] < 445.0 and corner[1] > 3.0


def test_a_point_outside_the_view_is_not_pulled_in():
    (box,) = place_labels([(600.0, 250.0)], [SIZE], VIEW)
    assert box[0] == 600.0 + GAP_X
