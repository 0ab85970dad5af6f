"""Case and area codes of a registration (Stumpe et al.), one definition with names, labels and colours.

``RegistrationResult.cases[source]`` holds :class:`Case` codes per target pixel and source camera,
``RegistrationResult.area`` :class:`Area` codes per target pixel (uint8 arrays; the integer values
are part of the output format and never change). The geometry behind each code is explained
in :mod:`.register`; overlay colours are the paper's (P2 cyan, P3.1 yellow, P3.2 magenta) plus
our choices (P5 orange, outside grey). ``colour`` None = no overlay (P1 and background need no mark).

To add a code: one member here and its entry in ``_CASE_INFO`` / ``_AREA_INFO``.
"""

from __future__ import annotations

from enum import IntEnum

RGB = tuple[int, int, int]


class Case(IntEnum):
    """Per source camera: what the target pixel's registered value is worth."""

    BACKGROUND = 0   # P6: target ray hits neither mesh
    P1 = 1           # legitimate
    P2 = 2           # occluded: the source ray meets the object mesh first
    P31 = 3          # incoming uncertain: target ray meets the uncertainty mesh first
    P32 = 4          # outgoing uncertain: source ray meets the uncertainty mesh first
    P5 = 5           # uncertain area, no object behind
    OUTSIDE = 6      # hit outside the source image or behind the source camera

    @property
    def label(self) -> str:
        return _CASE_INFO[self][0]

    @property
    def short(self) -> str:
        return _CASE_INFO[self][1]

    @property
    def colour(self) -> RGB | None:
        return _CASE_INFO[self][2]


class Area(IntEnum):
    """Target only: is the pixel certainly object, possibly object or background."""

    P4 = 4           # certain object
    P5 = 5           # uncertain object area
    P6 = 6           # certain background

    @property
    def label(self) -> str:
        return _AREA_INFO[self][0]

    @property
    def short(self) -> str:
        return _AREA_INFO[self][1]

    @property
    def colour(self) -> RGB | None:
        return _AREA_INFO[self][2]


# code -> (label, short label, overlay colour or None)
_CASE_INFO: dict[Case, tuple[str, str, RGB | None]] = {
    Case.BACKGROUND: ("P6 background", "P6", None),
    Case.P1: ("P1 legitimate", "P1", None),
    Case.P2: ("P2 occluded", "P2", (0, 255, 255)),
    Case.P31: ("P3.1 incoming uncertain", "P3.1", (255, 255, 0)),
    Case.P32: ("P3.2 outgoing uncertain", "P3.2", (255, 0, 255)),
    Case.P5: ("P5 uncertain area", "P5", (255, 140, 0)),
    Case.OUTSIDE: ("outside source", "out", (128, 128, 128)),
}
_AREA_INFO: dict[Area, tuple[str, str, RGB | None]] = {
    Area.P4: ("P4 certain object", "P4", (0, 255, 0)),
    Area.P5: ("P5 uncertain object", "P5", (255, 140, 0)),
    Area.P6: ("P6 certain background", "P6", None),
}

#: code -> label, code -> overlay colour (codes without an overlay left out): the dict views
#: older code and the summary file use.
CASE_NAMES: dict[int, str] = {int(c): c.label for c in Case}
AREA_NAMES: dict[int, str] = {int(a): a.label for a in Area}
CASE_COLOURS: dict[int, RGB] = {int(c): c.colour for c in Case if c.colour is not None}
AREA_COLOURS: dict[int, RGB] = {int(a): a.colour for a in Area if a.colour is not None}


def case_label(code: int) -> str:
    """Label of a case code, '?' for a value that is not a code."""
    try:
        return Case(int(code)).label
    except ValueError:
        return "?"


def area_label(code: int) -> str:
    try:
        return Area(int(code)).label
    except ValueError:
        return "?"


__all__ = ["Case", "Area", "CASE_NAMES", "AREA_NAMES", "CASE_COLOURS", "AREA_COLOURS", "case_label", "area_label"]
