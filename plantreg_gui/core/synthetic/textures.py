"""Appearance of the synthetic scene: texture functions of the 3D surface point.

Every modality is derived from one set of per-point quantities so that the modalities agree
with each other (a leaf spot is a spot in RGB, infrared, thermal and the spectral cube):

* ``abundance`` (N, E): linear mixture of endmembers (healthy leaf, pale leaf/vein, necrotic
  spot, soil, terracotta, ground, stem), to be scaled by illumination (Lambertian shading
  with a fixed light; the active infrared is lit from the camera). RGB, the active-infrared reflectance and the hyperspectral cube are
  linear in it, so supersampled pixels can be averaged before expanding to 204 bands.
* ``temperature`` (N,) degrees C for the thermal camera (no shading: emitted, not reflected).

Detail: veins, lateral veins and spots on leaves (0.5-6 mm), soil grain (1-3 mm), ground
tiles with joints and speckle, grooves on the pot -- enough that a one-pixel shift of any
camera is visible. The noise is a smoothed random lattice sampled with ``scipy.ndimage``
(trilinear), at several scales with rotated coordinates so the lattice never shows.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy import ndimage

from .scene import MAT_GROUND, MAT_LEAF0, MAT_POT, MAT_SOIL, MAT_STEM, Scene

# ---------------------------------------------------------------------- endmembers
E_LEAF, E_PALE, E_SPOT, E_SOIL, E_TERRA, E_GROUND, E_STEM = range(7)
N_END = 7
#: linear RGB albedo of each endmember
RGB_ALBEDO = np.array([
    [0.055, 0.190, 0.035],   # healthy leaf
    [0.200, 0.420, 0.110],   # pale leaf tissue / veins
    [0.420, 0.330, 0.060],   # necrotic / chlorotic spot
    [0.085, 0.055, 0.035],   # soil
    [0.560, 0.220, 0.110],   # terracotta
    [0.300, 0.285, 0.255],   # ground (concrete / gravel mat)
    [0.170, 0.300, 0.075],   # stem
])
#: reflectance at the time-of-flight camera's 850 nm illumination
NIR_850 = np.array([0.46, 0.64, 0.30, 0.16, 0.55, 0.38, 0.44])

_LIGHT = np.array([0.25, -0.20, -1.0]) / np.linalg.norm([0.25, -0.20, -1.0])  # towards the light, rig frame


def _vegetation(lam: np.ndarray, green: float, red: float, edge_nm: float, nir: float) -> np.ndarray:
    """Leaf reflectance: chlorophyll absorption in blue and red, green peak, red edge, NIR
    plateau, water dip near 970 nm."""
    vis = 0.045 + green * np.exp(-(((lam - 552) / 38) ** 2)) - 0.03 * np.exp(-(((lam - 675) / 18) ** 2))
    vis = vis + red * np.exp(-(((lam - 640) / 45) ** 2))
    edge = 1.0 / (1.0 + np.exp(-(lam - edge_nm) / 11.0))
    water = 0.06 * np.exp(-(((lam - 970) / 28) ** 2))
    return np.clip(vis * (1 - edge) + (nir - water) * edge, 0.005, 1.0)


def endmember_spectra(bands_nm: np.ndarray) -> np.ndarray:
    """Reflectance spectra (E, B) of the endmembers at the given wavelengths (nm)."""
    lam = np.asarray(bands_nm, dtype=np.float64)
    x = (lam - 400.0) / 600.0
    return np.stack([
        _vegetation(lam, 0.085, 0.00, 716, 0.47),                                  # healthy
        _vegetation(lam, 0.160, 0.05, 708, 0.62),                                  # pale / veins
        _vegetation(lam, 0.110, 0.20, 690, 0.36),                                  # spot (stressed)
        0.045 + 0.13 * x + 0.02 * x**2,                                            # soil
        0.07 + 0.46 / (1 + np.exp(-(lam - 585) / 28)) - 0.03 * x,                   # terracotta
        0.21 + 0.12 * x + 0.02 * np.sin(6 * x),                                    # ground
        _vegetation(lam, 0.120, 0.02, 712, 0.45),                                  # stem
    ]).astype(np.float32)


# ---------------------------------------------------------------------- noise
class Noise:
    """Band-limited value noise with unit standard deviation and features of ~``scale`` metres.

    3D: a periodic, Gaussian-smoothed random lattice (64^3) sampled trilinearly
    (``scipy.ndimage.map_coordinates``). 2D (for the flat ground, much faster): a 512^2 lattice
    sampled bilinearly with ``cv2.remap``. Each ``slot`` uses its own rotation and offset so that
    octaves and patterns do not align.
    """

    def __init__(self, seed: int, size: int = 64, size2: int = 512):
        rng = np.random.default_rng(seed)
        g = ndimage.gaussian_filter(rng.standard_normal((size, size, size)), 1.0, mode="wrap")
        self.grid = ((g - g.mean()) / g.std()).astype(np.float32)
        g2 = ndimage.gaussian_filter(rng.standard_normal((size2, size2)), 1.0, mode="wrap")
        self.grid2 = ((g2 - g2.mean()) / g2.std()).astype(np.float32)
        self.size, self.size2 = size, size2
        self._rots = [self._rotation(rng).astype(np.float32) for _ in range(32)]
        self._offs = rng.uniform(0, size, (32, 3)).astype(np.float32)
        ang = rng.uniform(0, 2 * np.pi, 32)
        self._rots2 = [np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]], np.float32) for a in ang]
        self._offs2 = rng.uniform(0, size2, (32, 2)).astype(np.float32)

    @staticmethod
    def _rotation(rng: np.random.Generator) -> np.ndarray:
        q, r = np.linalg.qr(rng.standard_normal((3, 3)))
        q *= np.sign(np.diag(r))
        return q if np.linalg.det(q) > 0 else -q

    def __call__(self, P: np.ndarray, scale: float, slot: int = 0) -> np.ndarray:
        """3D noise at points (N, 3) -> (N,) float32."""
        if len(P) == 0:
            return np.zeros(0, np.float32)
        # lattice spacing = scale / 2: after smoothing with sigma 1 features are ~scale wide
        R = self._rots[slot % 32] * np.float32(2.0 / scale)
        c = R @ np.asarray(P, dtype=np.float32).T          # (3, N), contiguous
        c += self._offs[slot % 32][:, None]
        return ndimage.map_coordinates(self.grid, c, order=1, mode="grid-wrap", prefilter=False)

    def flat(self, P: np.ndarray, scale: float, slot: int = 0) -> np.ndarray:
        """2D noise of the x, y coordinates of points (for horizontal surfaces) -> (N,) float32.
        ``P`` is (N, 3), or (2, N) float32 x and y rows (prepared once with :func:`xy_rows`)."""
        xy = P if P.shape[0] == 2 and P.dtype == np.float32 else xy_rows(P)
        n = xy.shape[1]
        if n == 0:
            return np.zeros(0, np.float32)
        cols = 4096  # cv2.remap wants maps under 32767 pixels per side
        m = -(-n // cols) * cols
        c = np.zeros((2, m), np.float32)
        R = self._rots2[slot % 32] * np.float32(2.0 / scale)
        np.matmul(R, xy, out=c[:, :n])
        c += self._offs2[slot % 32][:, None]
        np.mod(c, self.size2, out=c)  # remap converts coordinates to 16-bit fixed point
        out = cv2.remap(self.grid2, c[0].reshape(-1, cols), c[1].reshape(-1, cols), cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_WRAP)
        return out.ravel()[:n]

    def fbm(self, P: np.ndarray, scale: float, octaves: int = 3, slot: int = 0, flat: bool = False) -> np.ndarray:
        f = self.flat if flat else self.__call__
        out = np.zeros(P.shape[1] if flat and P.shape[0] == 2 else len(P), dtype=np.float32)
        amp, tot = 1.0, 0.0
        for o in range(octaves):
            out += np.float32(amp) * f(P, scale / 2**o, slot + o)
            tot += amp**2
            amp *= 0.55
        return out / np.float32(np.sqrt(tot))


def xy_rows(P: np.ndarray) -> np.ndarray:
    """x and y of points (N, 3) as contiguous float32 rows (2, N), the input of :meth:`Noise.flat`."""
    return np.ascontiguousarray(np.asarray(P)[:, :2].T, dtype=np.float32)


def _smoothstep(e0: float, e1: float, x: np.ndarray) -> np.ndarray:
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3 - 2 * t)


# ---------------------------------------------------------------------- per-point appearance
class Appearance:
    """Texture functions of the scene's surface points. Deterministic for the scene's seed."""

    def __init__(self, scene: Scene):
        self.scene = scene
        self.noise = Noise(10_000 + scene.seed)
        n = MAT_LEAF0 + max([lf.index for lf in scene.leaves], default=0) + 1
        # per-material lookup tables (index = material id)
        self.leaf_len = np.full(n, 0.15)
        self.leaf_tone = np.full(n, 0.5)
        for lf in scene.leaves:
            self.leaf_len[MAT_LEAF0 + lf.index] = lf.length
            self.leaf_tone[MAT_LEAF0 + lf.index] = lf.tone

    # -- geometry-derived helpers
    def shading(self, normal: np.ndarray) -> np.ndarray:
        """Two-sided Lambertian shading with ambient light, (N,)."""
        return 0.35 + 0.65 * np.abs(normal @ _LIGHT)

    def _tiles(self, P: np.ndarray) -> np.ndarray:
        """1 on the joints of a 12 cm tile pattern of the ground, 0 elsewhere."""
        q = (P[:, :2].astype(np.float32) + np.float32(0.03)) / np.float32(0.12)
        d = np.abs(q - np.round(q)).min(axis=1) * np.float32(0.12)  # distance to the nearest joint (m)
        return _smoothstep(0.0025, 0.0015, d)

    def _leaf_pattern(self, P: np.ndarray, uv: np.ndarray, mat: np.ndarray) -> dict[str, np.ndarray]:
        """Leaf texture fields (N,) each: ``veins`` (midrib, lateral and a finer network, 0..1),
        ``mottle`` (fine zero-mean variation), ``spots`` (0..1), ``chl`` (coarse chlorophyll
        variation), ``frac`` (position along the blade, 0 at the base, 1 at the tip)."""
        s, t = uv[:, 0], uv[:, 1]
        frac = np.clip(s / self.leaf_len[mat], 0, 1)
        at = np.abs(t)
        midrib = np.exp(-((at / (0.0013 * (1.2 - frac))) ** 2))
        spacing = 0.010
        phase = (s - 0.75 * at) / spacing
        d = np.abs(phase - np.round(phase)) * spacing * 0.8
        lateral = np.exp(-((d / 0.0008) ** 2)) * _smoothstep(0.0, 0.004, at) * (frac > 0.04)
        # a finer network: the zero crossings of a noise field are closed curves on the blade
        network = _smoothstep(0.22, 0.08, np.abs(self.noise(P, 0.006, slot=18)))
        veins = np.clip(midrib + 0.8 * lateral + 0.45 * network, 0, 1)
        mottle = 0.7 * self.noise(P, 0.0022, slot=7) + 0.5 * self.noise(P, 0.0045, slot=19)
        spotfield = self.noise(P, 0.006, slot=3) + 0.4 * self.noise(P, 0.0025, slot=4)
        spots = _smoothstep(1.55, 2.0, spotfield)
        chl = 0.5 * self.noise.fbm(P, 0.03, 2, slot=11)
        return {"veins": veins, "mottle": mottle, "spots": spots, "chl": chl, "frac": frac}

    # -- the shared per-point quantities
    def abundance(self, P: np.ndarray, mat: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """Endmember abundances (N, E) before shading (multiply by :meth:`shading`), float32."""
        A = np.zeros((len(P), N_END), dtype=np.float32)
        nz = self.noise

        sel = mat == MAT_GROUND
        if sel.any():
            p = P[sel]
            xy = xy_rows(p)
            b = np.clip(1.0 + 0.18 * nz.fbm(xy, 0.02, 2, slot=0, flat=True) + 0.12 * nz.flat(xy, 0.0015, slot=3), 0.3, None)
            wet = _smoothstep(0.5, 1.1, nz.flat(xy, 0.05, slot=4))
            joint = self._tiles(p)
            A[sel, E_GROUND] = b * (1 - 0.55 * wet) * (1 - 0.6 * joint)
            A[sel, E_SOIL] = b * (0.8 * wet + 0.6 * joint)

        sel = mat == MAT_POT
        if sel.any():
            p = P[sel]
            groove = _smoothstep(0.0009, 0.0003, np.abs(((p[:, 2] / 0.008) % 1.0 - 0.5) * 0.008))
            b = np.clip(1.0 + 0.12 * nz.fbm(p, 0.01, 3, slot=5), 0.5, None) - 0.35 * groove
            A[sel, E_TERRA] = b
            A[sel, E_SOIL] = 0.3 * _smoothstep(1.2, 1.8, nz(p, 0.004, slot=6))

        sel = mat == MAT_SOIL
        if sel.any():
            p = P[sel]
            grain = nz(p, 0.0012, slot=8) * 0.35 + nz(p, 0.004, slot=9) * 0.25
            perlite = _smoothstep(1.6, 2.1, nz(p, 0.003, slot=10))
            A[sel, E_SOIL] = np.clip(1.0 + grain, 0.2, None) * (1 - perlite)
            A[sel, E_GROUND] = 2.5 * perlite

        sel = mat == MAT_STEM
        if sel.any():
            p = P[sel]
            A[sel, E_STEM] = np.clip(1.0 + 0.15 * nz(p, 0.003, slot=12), 0.4, None)

        sel = mat >= MAT_LEAF0
        if sel.any():
            p, m = P[sel], mat[sel]
            f = self._leaf_pattern(p, uv[sel], m)
            spots = f["spots"]
            tone = self.leaf_tone[m]
            pale = np.clip(0.15 + 0.35 * tone + 0.25 * f["chl"] + 0.22 * f["mottle"], 0, 0.9)
            pale = np.clip(pale + 0.8 * f["veins"] * (1 - pale), 0, 1)
            A[sel, E_LEAF] = (1 - pale) * (1 - spots)
            A[sel, E_PALE] = pale * (1 - spots)
            A[sel, E_SPOT] = spots

        return A.astype(np.float32)

    def temperature(self, P: np.ndarray, mat: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """Surface temperature (N,) degrees C: leaves (19-23) cooler than soil, pot and ground (up to ~30)."""
        T = np.zeros(len(P), dtype=np.float32)
        nz = self.noise
        sel = mat == MAT_GROUND
        if sel.any():
            p = P[sel]
            xy = xy_rows(p)
            T[sel] = 28.0 + 2.0 * (p[:, 0] + 0.5) - 0.8 * p[:, 1] + 0.5 * nz.fbm(xy, 0.015, 2, slot=13, flat=True) \
                - 1.2 * self._tiles(p) - 1.5 * _smoothstep(0.5, 1.1, nz.flat(xy, 0.05, slot=4))
        sel = mat == MAT_POT
        if sel.any():
            p = P[sel]
            T[sel] = 25.5 + 1.5 * (p[:, 2] - (self.scene.ground_z - 0.14)) / 0.14 + 0.3 * nz.fbm(p, 0.008, 2, slot=14)
        sel = mat == MAT_SOIL
        if sel.any():
            p = P[sel]
            T[sel] = 23.0 + 0.6 * nz(p, 0.003, slot=8) + 0.3 * nz(p, 0.0012, slot=15)
        sel = mat == MAT_STEM
        if sel.any():
            T[sel] = 22.0 + 0.2 * nz(P[sel], 0.004, slot=16)
        sel = mat >= MAT_LEAF0
        if sel.any():
            p, m = P[sel], mat[sel]
            f = self._leaf_pattern(p, uv[sel], m)
            tone = self.leaf_tone[m]
            # transpiring tissue is cool; veins and tips warmer, necrotic spots do not transpire
            T[sel] = (20.0 + 1.2 * tone + 1.0 * f["frac"] + 0.9 * f["veins"] + 2.0 * f["spots"]
                      + 0.25 * f["mottle"] + 0.3 * nz.fbm(p, 0.01, 2, slot=17))
        return T.astype(np.float32)
