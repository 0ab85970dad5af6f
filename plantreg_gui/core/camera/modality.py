"""The one registry of imaging modalities: what a camera's ``modality`` string means.

A rig file, a calibration session or the wizard may call the same kind of camera ``"visible"``,
``"colour"`` or ``"rgb"``, a thermal camera ``"lwir"`` or ``"thermal"``. Everything that depends on
the kind of camera (default colour map, unit of the values, board polarity for detection, how
many channels to expect, which camera colours a point cloud) asks this module; nobody else
compares modality strings. Names are canonicalised when a rig or a session is loaded
(:meth:`~plantreg_gui.core.camera.camera.Camera.from_dict`, the calibration session).

To add a modality: add one :class:`Modality` to :data:`MODALITIES`.
"""

from __future__ import annotations

from dataclasses import dataclass

#: Colour map for single-band images of a modality not in the registry.
FALLBACK_CMAP = "gray"


@dataclass(frozen=True)
class Modality:
    """What plantreg knows about one kind of camera.

    ``name`` canonical (what a loaded rig holds); ``aliases`` other spellings (lower case);
    ``cmap`` default matplotlib colour map of a single band; ``unit`` of the pixel values ('' =
    arbitrary); ``inverted_board`` a calibration board appears as a photographic negative
    (heated board in a thermal camera); ``channels`` expected bands: 1, 3, or 0 = many (cubes);
    ``label`` for people; ``zero_is_missing``: a value <= 0 means "no measurement" (depth maps).
    """

    name: str
    aliases: tuple[str, ...] = ()
    cmap: str = FALLBACK_CMAP
    unit: str = ""
    inverted_board: bool = False
    channels: int = 1
    label: str = ""
    zero_is_missing: bool = False

    @property
    def is_colour(self) -> bool:
        """True for colour cameras (their 3 channels are R, G, B, not bands to stretch apart)."""
        return self.channels == 3

    @property
    def is_cube(self) -> bool:
        """True for spectral cubes (any band count; PCA false colour, spectra, band pickers)."""
        return self.channels == 0


MODALITIES: tuple[Modality, ...] = (
    Modality("rgb", ("visible", "colour", "color", "bgr", "rgba", "vis"), "gray", "", False, 3, "colour (RGB)"),
    Modality("thermal", ("lwir", "ir-thermal", "thermal-ir", "tir", "temperature", "thermography"),
             "RdBu_r", "°C", True, 1, "thermal"),  # diverging blue-white-red like the paper's figures
    Modality("infrared", ("nir", "ir", "infra", "infra-red", "tof", "amplitude", "swir"), "gray", "", False, 1,
             "infrared"),
    Modality("hyperspectral", ("hsi", "hyper", "multispectral", "spectral", "msi"), "gray", "", False, 0,
             "hyperspectral"),
    Modality("depth", ("range", "distance", "z"), "viridis", "mm", False, 1, "depth", zero_is_missing=True),
)

_BY_NAME: dict[str, Modality] = {}
for _m in MODALITIES:
    for _key in (_m.name, *_m.aliases):
        _BY_NAME[_key] = _m


def _key(name: str | None) -> str:
    return (name or "").strip().lower().replace("_", "-").replace(" ", "-")


def canonical(name: str | None) -> str:
    """The canonical name of a modality string (``'visible'`` -> ``'rgb'``, ``'LWIR'`` -> ``'thermal'``);
    an unknown name is returned stripped and lower-cased (``''`` for None)."""
    k = _key(name)
    m = _BY_NAME.get(k)
    return m.name if m is not None else k


def get(name: str | None) -> Modality:
    """The :class:`Modality` of any spelling; an unknown name gets a neutral entry (grey, no unit)."""
    m = _BY_NAME.get(_key(name))
    if m is not None:
        return m
    k = _key(name) or "unknown"
    return Modality(k, label=k)


def names() -> list[str]:
    """Canonical names, in registry order (for choosers)."""
    return [m.name for m in MODALITIES]


def is_colour(name: str | None) -> bool:
    return get(name).is_colour


def is_cube(name: str | None) -> bool:
    return get(name).is_cube


def is_cube_image(name: str | None, bands: int) -> bool:
    """Whether an image of ``bands`` bands from a camera of modality ``name`` is a spectral cube
    (band pickers, spectra, PCA false colour, a read-out at one band): the one rule. More than
    four bands always; four unless the camera is a colour camera (RGBA); three for a cube modality
    (a hyperspectral camera's own 3-band rendering)."""
    m = get(name)
    return bands > 4 or (bands == 4 and not m.is_colour) or (bands == 3 and m.is_cube)


def default_cmap(name: str | None) -> str:
    return get(name).cmap


def unit(name: str | None) -> str:
    return get(name).unit


def inverted_board(name: str | None) -> bool:
    """Board polarity assumed by detection when the user did not choose: thermal = inverted."""
    return get(name).inverted_board


def guess(name: str, channels: int) -> str:
    """A modality for an image without a rig entry, from its name and band count (raw inspection only)."""
    n = _key(name)
    if n in _BY_NAME:
        return _BY_NAME[n].name
    for m in MODALITIES:
        if any(a in n for a in (m.name, *m.aliases) if len(a) >= 3):
            return m.name
    if channels > 4:
        return "hyperspectral"
    return "rgb" if channels in (3, 4) else "infrared"


__all__ = ["Modality", "MODALITIES", "canonical", "get", "names", "is_colour", "is_cube", "is_cube_image", "default_cmap",
           "unit", "inverted_board", "guess"]
