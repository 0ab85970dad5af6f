"""Where the landmark views put their point labels: pure geometry in screen pixels, no Qt.

Each label is a box of the text's size next to its marker. The candidate places are tried in a
fixed order -- right above (the usual place), right below, left above, left below, beside, over,
under, then the same further out -- and a label takes the first that stays inside the view and
overlaps neither an already placed label nor another marker. When none is free it takes the one
with the least overlap (ties: the earlier). Labels are placed in the order given, so the same
points at the same zoom always get the same picture.
"""

from __future__ import annotations

from typing import Sequence

Box = tuple[float, float, float, float]  # x0, y0, x1, y1 (screen pixels, y down)

#: horizontal gap between a marker's centre and its label (the marker's radius is 5 px)
GAP_X = 8.0
#: vertical gap between a marker's centre and a label above or below it
GAP_Y = 3.0
#: half the size of the square a marker occupies (circle of radius 5 drawn with a 4 px halo)
MARKER_HALF = 7.0
#: rings of candidate places: ring k moves the label k label-heights further away
RINGS = 3


def _overlap(a: Box, b: Box) -> float:
    w = min(a[2], b[2]) - max(a[0], b[0])
    h = min(a[3], b[3]) - max(a[1], b[1])
    return w * h if w > 0 and h > 0 else 0.0


def _outside(a: Box, bounds: Box) -> float:
    """Area of ``a`` outside ``bounds``."""
    area = (a[2] - a[0]) * (a[3] - a[1])
    return area - _overlap(a, bounds)


def candidates(x: float, y: float, w: float, h: float) -> list[Box]:
    """Label boxes of size ``w`` x ``h`` around a marker at ``(x, y)``, in order of preference."""
    out: list[Box] = []
    for k in range(RINGS):
        up, down = y - GAP_Y - h - k * h, y + GAP_Y + k * h
        right, left = x + GAP_X + k * h, x - GAP_X - w - k * h
        places = [(right, up), (right, down), (left, up), (left, down)]
        if k == 0:  # level with the marker, then centred over or under it
            places += [(right, y - h / 2), (left, y - h / 2), (x - w / 2, up - 4), (x - w / 2, down + 4)]
        out += [(px, py, px + w, py + h) for px, py in places]
    return out


def place_labels(anchors: Sequence[tuple[float, float]], sizes: Sequence[tuple[float, float]],
                 bounds: Box) -> list[Box]:
    """Boxes ``(x0, y0, x1, y1)`` of the labels of markers at ``anchors`` (screen pixels), the
    labels' sizes ``(w, h)`` in ``sizes``, inside the view ``bounds`` when they can be.

    A marker outside the view keeps the usual place (its label is not pulled into sight away from
    its point). Overlaps with other markers count as much as overlaps with labels.
    """
    markers = [(x - MARKER_HALF, y - MARKER_HALF, x + MARKER_HALF, y + MARKER_HALF) for x, y in anchors]
    placed: list[Box] = []
    for i, ((x, y), (w, h)) in enumerate(zip(anchors, sizes)):
        cands = candidates(x, y, w, h)
        if not (bounds[0] <= x <= bounds[2] and bounds[1] <= y <= bounds[3]):
            placed.append(cands[0])
            continue
        best, best_cost = cands[0], None
        for c in cands:
            # leaving the view is worse than any overlap: a cut label cannot be read at all
            cost = 1e6 * _outside(c, bounds)
            cost += sum(_overlap(c, p) for p in placed)
            cost += sum(_overlap(c, m) for j, m in enumerate(markers) if j != i)
            if cost == 0:
                best = c
                break
            if best_cost is None or cost < best_cost:
                best, best_cost = c, cost
        placed.append(best)
    return placed


def leader_end(anchor: tuple[float, float], box: Box, near: float = 12.0) -> tuple[float, float] | None:
    """The point of ``box`` nearest to ``anchor`` when the label sits farther than ``near`` pixels
    from its marker (then a thin line joins them), else None."""
    x, y = anchor
    px, py = min(max(x, box[0]), box[2]), min(max(y, box[1]), box[3])
    if ((px - x) ** 2 + (py - y) ** 2) ** 0.5 <= near:
        return None
    return px, py


__all__ = ["candidates", "place_labels", "leader_end"]
