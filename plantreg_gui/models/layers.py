"""What the registration workspace shows, computed without Qt.

The widgets only display what this module computes: display renderings of images (through
:func:`plantreg_gui.core.display.display.to_rgb8`, the same rendering as the CLI previews), read-outs
of every modality at a pixel in its units, and the multimodal point cloud as arrays. Keeping it
Qt-free means it can be tested headless and used on a worker thread.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..core.display import display
from ..core.camera import modality as _mod
from ..core.geometry.depth import to_millimetres

DEPTH = "depth"  # pseudo-modality: z of the hit point (registered) or the raw depth map

#: colour maps offered in the display controls (matplotlib names)
COLORMAPS = ["gray", "viridis", "magma", "inferno", "RdBu_r", "coolwarm", "bwr", "jet", "turbo"]


@dataclass
class DisplaySettings:
    """How one modality is drawn. ``cmap`` None = the modality's default (thermal RdBu_r,
    infrared gray, depth viridis); ``bands`` None = PCA false colour for cubes. ``limits``
    absolute (lo, hi) in the layer's unit (e.g. 18-26 °C), used instead of the ``percentiles``
    when set; ``locked`` keeps them when another recording is opened (so colours compare
    between recordings), otherwise a new recording goes back to the percentiles."""

    cmap: str | None = None
    percentiles: tuple[float, float] = (1.0, 99.0)
    bands: tuple[int, int, int] | None = None
    limits: tuple[float, float] | None = None
    locked: bool = False

    def with_(self, **kw: Any) -> "DisplaySettings":
        return replace(self, **kw)


def render(img: np.ndarray, modality: str, settings: DisplaySettings | None = None,
           pca: display.PcaBasis | None = None) -> np.ndarray:
    """Any image (H, W[, C]) -> (H, W, 3) uint8, as the core renders it for previews. ``pca``: the
    false-colour basis of this camera's raw cube, so raw and registered cubes look alike."""
    s = settings or DisplaySettings()
    bands = s.bands
    if bands is not None and (img.ndim != 3 or not _mod.is_cube_image(modality, img.shape[2])):
        bands = None
    limits = s.limits if s.limits is not None and pca is None else None  # PCA colours have no unit
    return display.to_rgb8(img, modality=modality, cmap=s.cmap, limits=limits, percentiles=s.percentiles,
                           bands=bands, pca=pca)


def pca_basis(raw: np.ndarray, modality: str, settings: DisplaySettings | None = None) -> display.PcaBasis | None:
    """The PCA false-colour basis of a raw cube (None for images that are not cubes)."""
    if raw.ndim != 3 or not _mod.is_cube_image(modality, raw.shape[2]):
        return None
    if display.shows_as_rgb(raw.shape[2], modality):  # a 3-band cube is drawn as RGB, raw and registered
        return None
    return display.fit_pca(raw, None, (settings or DisplaySettings()).percentiles)


#: spellings of a rig's ``units`` -> the unit as shown
_UNIT_SPELLINGS = {"degc": "°C", "°c": "°C", "celsius": "°C", "c": "°C", "k": "K", "kelvin": "K",
                   "mm": "mm", "millimetre": "mm", "millimeter": "mm"}


def unit_of(modality: str, cam: Any = None) -> str:
    """The unit of a camera's values: the rig's ``units`` when it states them (a thermal camera
    in kelvin is K, not °C), else the modality's."""
    u = (getattr(cam, "extra", None) or {}).get("units") if cam is not None else None
    if isinstance(u, str) and u.strip():
        return _UNIT_SPELLINGS.get(u.strip().lower(), u.strip())
    return _mod.unit(modality)


def format_value(v: float, modality: str, unit: str | None = None) -> str:
    """A value with its unit (``unit`` None: the modality's)."""
    if not np.isfinite(v):
        return "—"
    unit = _mod.unit(modality) if unit is None else unit
    if unit in ("°C", "K"):
        return f"{v:.2f} {unit}"
    if unit == "mm":
        return f"{v:.1f} mm"
    num = f"{v:.0f}" if abs(v) >= 1000 or float(v).is_integer() else f"{v:.4g}"
    return f"{num} {unit}" if unit else num


def _same_decimals(vals: list[float]) -> list[str]:
    """A colour triple's values with one number of decimals (a registered render's values are
    resampled: "(17, 34.09, 17)" read like a glitch): none if all are whole, else by the largest."""
    if all(float(v).is_integer() for v in vals):
        return [f"{v:.0f}" for v in vals]
    m = max(abs(v) for v in vals)
    d = 3 if m < 1 else 2 if m < 10 else 1 if m < 1000 else 0
    return [f"{v:.{d}f}" for v in vals]


@dataclass
class Layer:
    """One displayable image: a camera's (raw or registered) image or the depth."""

    name: str
    modality: str
    data: np.ndarray                          # (H, W) or (H, W, B)
    wavelengths: np.ndarray | None = None     # (B,) nm, for cubes when known
    unit: str = ""

    @property
    def bands(self) -> int:
        return 1 if self.data.ndim == 2 else int(self.data.shape[2])

    @property
    def is_cube(self) -> bool:
        """A spectral cube (the modality registry's one rule: ``modality.is_cube_image``)."""
        return _mod.is_cube_image(self.modality, self.bands)

    @property
    def middle_band(self) -> int | None:
        """The band a cube is read out at when none is chosen (None: not a cube)."""
        return self.bands // 2 if self.is_cube else None

    def percentile_limits(self, percentiles: tuple[float, float]) -> tuple[float, float]:
        """``display.auto_limits`` of the data (all bands pooled), remembered per percentiles: the
        colour bar and the start of absolute limits ask for the same numbers, and a large cube's
        would be recomputed on the GUI thread each time. (The 2D rendering takes its own, in
        ``display.to_rgb8``: for depth it first drops values <= 0.)"""
        cache = self.__dict__.setdefault("_limits", {})
        key = (id(self.data), float(percentiles[0]), float(percentiles[1]))
        if key not in cache:
            cache[key] = tuple(float(v) for v in display.auto_limits(self.data, percentiles))
        return cache[key]

    #: at most this many values enter a histogram (a strided sample of a larger image)
    HIST_SAMPLE = 1 << 18

    def histogram(self, bins: int = 64) -> tuple[np.ndarray, np.ndarray] | None:
        """(counts (bins,), edges (bins + 1,)) of a single-band layer's finite values (depth:
        values > 0), over a strided sample of at most :attr:`HIST_SAMPLE` pixels; None for
        colour and multi-band images or no finite value. Cached per layer."""
        if self.data.ndim != 2:
            return None
        cache = self.__dict__.setdefault("_hist", {})
        key = (id(self.data), bins)
        if key not in cache:
            flat = self.data.reshape(-1)
            step = max(1, flat.size // self.HIST_SAMPLE)
            v = np.asarray(flat[::step], dtype=np.float64)
            v = v[np.isfinite(v)]
            if _mod.get(self.modality).zero_is_missing:
                v = v[v > 0]
            cache[key] = None if v.size == 0 else np.histogram(v, bins=bins)
        return cache[key]

    def value_text(self, row: int, col: int, band: int | None = None) -> str:
        h, w = self.data.shape[:2]
        if not (0 <= row < h and 0 <= col < w):
            return "—"
        px = self.data[row, col]
        if self.data.ndim == 2:
            return format_value(float(px), self.modality, self.unit)
        if display.shows_as_rgb(self.bands, self.modality):  # drawn as RGB (a 3-band cube too): its values
            if not np.all(np.isfinite(px.astype(np.float64))):
                return "—"
            vals = "(" + ", ".join(_same_decimals([float(v) for v in px])) + ")"
            return f"{vals} {self.unit}" if self.unit else vals  # the unit once, not per channel
        b = 0 if band is None else int(np.clip(band, 0, self.bands - 1))
        v = float(px[b])
        where = f"{self.wavelengths[b]:.0f} nm" if self.wavelengths is not None else f"band {b}"
        return f"{format_value(v, self.modality, self.unit)} @ {where} ({self.bands} bands)"

    def spectrum(self, row: int, col: int) -> np.ndarray | None:
        """(B,) values of a cube at a pixel, None for images with at most 3 bands."""
        if self.data.ndim != 3 or self.bands <= 3:
            return None
        h, w = self.data.shape[:2]
        if not (0 <= row < h and 0 <= col < w):
            return None
        return np.asarray(self.data[row, col], dtype=np.float64)


def colour_bar_of(L: Layer, settings: DisplaySettings | None = None
                  ) -> tuple[str | None, tuple[float, float] | None, str]:
    """(colour map, (lo, hi) limits in the layer's unit, unit) of a single-band layer as :func:`render`
    draws it with ``settings`` (default: the modality's colour map, 1-99 percentiles); (None, None, '')
    for colour and multi-band images (no colour bar). What every view's ColourBar shows."""
    if L.bands != 1:
        return None, None, ""
    st = settings or DisplaySettings()
    lim = st.limits if st.limits is not None else L.percentile_limits(st.percentiles)
    return st.cmap or _mod.default_cmap(L.modality), lim, L.unit


def wavelengths_of(camera: Any, bands: int) -> np.ndarray | None:
    """Band centres (nm) from a camera's extra rig keys (``wavelengths``/``wavelengths_nm``), if any."""
    extra = getattr(camera, "extra", {}) or {}
    for key in ("wavelengths_nm", "wavelengths", "bands_nm", "bands"):
        w = extra.get(key)
        if w is not None:
            w = np.asarray(w, dtype=np.float64).ravel()
            if w.size == bands:
                return w
    return None


def registered_layers(result: Any, rig: Any) -> list[Layer]:
    """The layers of a registration result in the target grid: every camera's registered
    image (target first) and the depth (z of the hit point, mm)."""
    layers = []
    names = list(result.registered)
    names.sort(key=lambda n: (n != result.target, rig.names.index(n) if n in rig.names else 99))
    for name in names:
        cam = rig.camera(name) if name in rig.names else None
        data = result.registered[name]
        mod = cam.modality if cam is not None else name
        layers.append(Layer(name, mod, data, wavelengths_of(cam, data.shape[2]) if data.ndim == 3 else None,
                            unit_of(mod, cam)))
    z_mm = np.asarray(result.points_rig[..., 2], dtype=np.float32) * np.float32(1000.0)
    layers.append(Layer(DEPTH, DEPTH, z_mm, None, "mm"))
    return layers


def raw_layers(rig: Any | None, recording: Any) -> list[Layer]:
    """The recording's raw images (depth first, in mm when the rig gives the scale)."""
    layers = []
    if recording.depth is not None:
        scale = getattr(recording, "depth_scale", None) or (rig.depth_scale if rig is not None else 0.001)
        d = to_millimetres(recording.depth, scale)
        layers.append(Layer(DEPTH, DEPTH, d, None, "mm"))
    for name, img in recording.images.items():
        cam = None
        if rig is not None and name in rig.names:
            cam = rig.camera(name)
        mod = cam.modality if cam is not None else _guess_modality(name, img)
        wl = wavelengths_of(cam, img.shape[2]) if (cam is not None and img.ndim == 3) else None
        layers.append(Layer(name, mod, img, wl, unit_of(mod, cam)))
    return layers


def _guess_modality(name: str, img: np.ndarray) -> str:
    return _mod.guess(name, 1 if img.ndim == 2 else img.shape[2])


@dataclass
class Cloud:
    """The multimodal point cloud of a registration: ``points`` (N, 3) rig frame metres,
    ``pixels`` (N,) flat target pixel index of each point, ``colours[name]`` (N, 3) uint8 (the
    display rendering of every layer, so 2D and 3D look the same), ``values[name]`` (N,) or
    (N, B) raw values for picking."""

    points: np.ndarray
    pixels: np.ndarray
    colours: dict[str, np.ndarray] = field(default_factory=dict)
    values: dict[str, np.ndarray] = field(default_factory=dict)
    modalities: dict[str, str] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)      # name -> unit (the layer's); else the modality's

    def point_text(self, i: int, previous: int | None = None) -> str:
        """Point ``i``'s position and every layer's value there, each with its unit; lengths in
        millimetres throughout (the points are stored in metres). With ``previous`` (an earlier
        pick), the distance between the two points too."""
        p = self.points[i].astype(np.float64)
        lines = [f"point {i}: x={p[0]*1000:.1f} y={p[1]*1000:.1f} z={p[2]*1000:.1f} mm (rig frame), "
                 f"{np.linalg.norm(p)*1000:.1f} mm from the rig origin"]
        if previous is not None and previous != i and 0 <= previous < len(self.points):
            q = self.points[previous].astype(np.float64)
            lines.append(f"distance to point {previous} (previous pick): {np.linalg.norm(p - q)*1000:.1f} mm")
        for name, v in self.values.items():
            unit = self.units.get(name)
            unit = _mod.unit(self.modalities.get(name, name)) if unit is None else unit
            if v.ndim == 1:
                lines.append(f"{name}: {format_value(float(v[i]), self.modalities.get(name, name), self.units.get(name))}")
            elif v.shape[1] == 3:
                lines.append(f"{name}: (" + ", ".join(_same_decimals([float(x) for x in v[i]])) + ")"
                             + (f" {unit}" if unit else ""))
            else:
                x = np.asarray(v[i], np.float64)
                if not np.isfinite(x).any():  # no value of this camera at the point
                    lines.append(f"{name}: {v.shape[1]} bands, —")
                    continue
                lines.append(f"{name}: {v.shape[1]} bands, mean {float(np.nanmean(x)):.4g}" + (f" {unit}" if unit else ""))
        return "\n".join(lines)


def build_cloud(points_hw3: np.ndarray, layers: list[Layer], renders: dict[str, np.ndarray]) -> Cloud:
    """Points with a finite position (from (H, W, 3)) and their per-layer colours/values."""
    flat = points_hw3.reshape(-1, 3)
    pix = np.flatnonzero(np.all(np.isfinite(flat), axis=1))
    cloud = Cloud(np.ascontiguousarray(flat[pix], dtype=np.float32), pix)
    for L in layers:
        if L.data.shape[:2] != points_hw3.shape[:2]:
            continue
        v = L.data.reshape(L.data.shape[0] * L.data.shape[1], -1)[pix]
        cloud.values[L.name] = v[:, 0] if v.shape[1] == 1 else v
        cloud.modalities[L.name] = L.modality
        cloud.units[L.name] = L.unit
        if L.name in renders:
            cloud.colours[L.name] = np.ascontiguousarray(renders[L.name].reshape(-1, 3)[pix])
    return cloud


def case_table(codes: np.ndarray, names: dict[int, str], colours: dict[int, Any]) -> list[tuple[int, str, Any, int, float]]:
    """Legend rows ``(code, name, rgb or None, count, percent)`` for every named code."""
    counts = np.bincount(np.asarray(codes, dtype=np.uint8).ravel(), minlength=256)
    total = max(int(codes.size), 1)
    return [(c, names[c], colours.get(c), int(counts[c]), 100.0 * counts[c] / total) for c in sorted(names)]
