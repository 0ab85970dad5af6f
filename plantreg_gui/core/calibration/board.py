"""Calibration boards: chessboard and ChArUco.

Board frame (used for every board type): origin at the first inner corner, x along a row of
inner corners (``columns`` of them), y along a column (``rows`` of them), z = x cross y, i.e.
pointing *into* the printed side (away from a camera that sees the print). Metres.

Corner order (the order of :meth:`Board.object_points` and of every detection):
row by row, ``index = j * columns + i`` for corner ``(i, j)`` at ``(i * s, j * s, 0)``.

Square colours (chessboard): the square whose *lower-right* corner is inner corner (0, 0)
(the outer top-left square of the printed board) is black; colours alternate. So the square
``(a, b)`` covering ``[a s, (a+1) s] x [b s, (b+1) s]`` (``a`` in ``-1 .. columns-1``) is black
when ``a + b`` is even. A board with ``columns + rows`` odd is *asymmetric*: rotated by 180
degrees its pattern differs, which is how detections get a unique order (see
:mod:`.detect`). Prefer asymmetric boards (e.g. 15 x 8, 9 x 6 inner corners).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

BOARD_TYPES = ("chessboard", "charuco")


def _aruco_dictionary(name: str):
    const = getattr(cv2.aruco, str(name).upper(), None)
    if not isinstance(const, int):
        raise ValueError(f"unknown ArUco dictionary '{name}' (e.g. DICT_4X4_50, DICT_5X5_100)")
    return cv2.aruco.getPredefinedDictionary(const)


#: Largest board square (or marker) side, metres: a calibration target with larger squares would
#: not fit a phenotyping rig's view (a typical one has 20-60 mm).
MAX_SQUARE_M = 1.0
#: Smallest: a printed square of a tenth of a millimetre is beyond any camera of such a rig.
MIN_SQUARE_M = 1e-4


@dataclass
class Board:
    """A planar calibration target.

    ``columns``/``rows`` count *inner* corners (a chessboard of 16 x 9 squares has 15 x 8).
    ``square_size`` and ``marker_size`` in metres; ``dictionary`` is an OpenCV ArUco dictionary
    name (``"DICT_4X4_50"``) for ChArUco boards.
    """

    type: str = "chessboard"
    columns: int = 9
    rows: int = 6
    square_size: float = 0.025
    marker_size: float | None = None
    dictionary: str | None = None

    def __post_init__(self) -> None:
        self.type = str(self.type).lower()
        self.columns = int(self.columns)
        self.rows = int(self.rows)
        self.square_size = float(self.square_size)
        self.validate()

    def validate(self) -> None:
        """Raise ``ValueError`` with a readable message if the geometry is impossible."""
        if self.type not in BOARD_TYPES:
            raise ValueError(f"board type '{self.type}' is not one of {', '.join(BOARD_TYPES)}")
        if self.columns < 2 or self.rows < 2:
            raise ValueError(
                f"a board needs at least 2 x 2 inner corners, got {self.columns} x {self.rows} "
                "(count the inner corners, where four squares meet, not the squares)"
            )
        if not self.square_size > 0:
            raise ValueError("square_size must be positive (metres)")
        if self.type == "charuco":
            if self.marker_size is None or not 0 < float(self.marker_size) < self.square_size:
                raise ValueError("a ChArUco board needs 0 < marker_size < square_size (metres)")
            self.marker_size = float(self.marker_size)
            if not self.dictionary:
                raise ValueError("a ChArUco board needs an ArUco 'dictionary' (e.g. DICT_4X4_50)")
            _aruco_dictionary(self.dictionary)
            n_markers = ((self.columns + 1) * (self.rows + 1)) // 2
            size = int(str(self.dictionary).upper().split("_")[-1]) if str(self.dictionary).split("_")[-1].isdigit() else None
            if size is not None and n_markers > size:
                raise ValueError(f"the board needs {n_markers} markers but {self.dictionary} has only {size}")

    # ------------------------------------------------------------------ geometry
    @property
    def pattern_size(self) -> tuple[int, int]:
        """(columns, rows) of inner corners, OpenCV's ``patternSize``."""
        return (self.columns, self.rows)

    @property
    def n_corners(self) -> int:
        return self.columns * self.rows

    @property
    def is_symmetric(self) -> bool:
        """True if the chessboard pattern looks the same rotated by 180 degrees
        (``columns + rows`` even): detections of it cannot be ordered uniquely."""
        return self.type == "chessboard" and (self.columns + self.rows) % 2 == 0

    @property
    def size_m(self) -> tuple[float, float]:
        """Printed pattern size (width, height) in metres, squares only."""
        return ((self.columns + 1) * self.square_size, (self.rows + 1) * self.square_size)

    def object_points(self) -> np.ndarray:
        """Inner corners in the board frame, (N, 3) float64, in corner order."""
        j, i = np.mgrid[0 : self.rows, 0 : self.columns]
        pts = np.zeros((self.n_corners, 3))
        pts[:, 0] = i.ravel() * self.square_size
        pts[:, 1] = j.ravel() * self.square_size
        return pts

    def square_is_black(self, a: np.ndarray | int, b: np.ndarray | int) -> np.ndarray | bool:
        """Colour of square ``(a, b)`` (see module docstring); ``a``/``b`` may be arrays."""
        return (np.asarray(a) + np.asarray(b)) % 2 == 0

    def charuco(self):
        """The OpenCV ``CharucoBoard`` (ChArUco boards only)."""
        if self.type != "charuco":
            raise ValueError("not a ChArUco board")
        b = cv2.aruco.CharucoBoard(
            (self.columns + 1, self.rows + 1), self.square_size, float(self.marker_size),
            _aruco_dictionary(str(self.dictionary)),
        )
        return b

    # ------------------------------------------------------------------ preview
    def render(self, px_per_square: int = 40, margin_squares: float = 0.5) -> np.ndarray:
        """A picture of the printed board (uint8, (H, W)), white margin around the squares.

        The first inner corner (the board origin) is at pixel
        ``((1 + margin_squares) * px_per_square - 0.5, same)``.
        """
        p = int(px_per_square)
        m = int(round(margin_squares * p))
        nx, ny = self.columns + 1, self.rows + 1
        if self.type == "charuco":
            img = self.charuco().generateImage((nx * p, ny * p), marginSize=0, borderBits=1)
        else:
            b, a = np.mgrid[0:ny, 0:nx]
            sq = np.where(self.square_is_black(a - 1, b - 1), 0, 255).astype(np.uint8)
            img = np.kron(sq, np.ones((p, p), np.uint8))
        return cv2.copyMakeBorder(img, m, m, m, m, cv2.BORDER_CONSTANT, value=255)

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"type": self.type, "columns": self.columns, "rows": self.rows,
                             "square_size": self.square_size}
        if self.type == "charuco":
            d["marker_size"] = self.marker_size
            d["dictionary"] = self.dictionary
        return d

    @classmethod
    def from_dict(cls, d: Any) -> "Board":
        """Build from the session's ``"board"`` object; raises ``ValueError`` with a readable message."""
        if not isinstance(d, dict):
            raise ValueError("\"board\" must be an object {\"type\", \"columns\", \"rows\", \"square_size\"}")
        missing = [k for k in ("columns", "rows", "square_size") if k not in d]
        if missing:
            raise ValueError(f"board lacks {', '.join(missing)}")
        from ..validate import number, positive_int

        from ..validate import show

        for k in ("columns", "rows"):  # int() would silently make 8.5 corners 8
            try:
                positive_int(d[k], f"board.{k}", 1000)
            except ValueError:
                raise ValueError(f"board: {k} must be a whole number of inner corners (1 to 1000), "
                                 f"got {show(d[k])}") from None
        for k in ("square_size", "marker_size"):
            if k == "square_size" or d.get(k) is not None:
                s = number(d[k], f"board.{k} (metres)", positive=True)
                if s > MAX_SQUARE_M:
                    raise ValueError(f"board.{k} is {show(d[k])} m; the sanity bound is {MAX_SQUARE_M:g} m (metres: "
                                     "millimetres by mistake?)")
                if s < MIN_SQUARE_M:  # 5e-324 m: every view "could not be calibrated", the board not named
                    raise ValueError(f"board.{k} is {show(d[k])} m; the sanity bound is at least {MIN_SQUARE_M:g} m "
                                     "(0.1 mm; metres: kilometres by mistake?)")
        try:
            return cls(
                type=str(d.get("type", "chessboard")),
                columns=int(d["columns"]),
                rows=int(d["rows"]),
                square_size=float(d["square_size"]),
                marker_size=None if d.get("marker_size") is None else float(d["marker_size"]),
                dictionary=d.get("dictionary"),
            )
        except (TypeError, ValueError) as e:
            raise ValueError(f"board: {e}") from None

    def describe(self) -> str:
        s = f"{self.type} {self.columns}x{self.rows} inner corners, {1000 * self.square_size:g} mm squares"
        if self.type == "charuco":
            s += f", {1000 * float(self.marker_size):g} mm markers ({self.dictionary})"
        return s
