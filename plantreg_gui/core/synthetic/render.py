"""Rendering a recording of the true scene, and the registration ground truth.

Every image is made by casting each camera's pixel rays -- through its distortion model, as
:meth:`Camera.rays_rig` -- into the true mesh and evaluating the material's texture at the hit.
Images are 2x2 supersampled (light anti-aliasing) when the camera has at most ~2 Mpx; the depth
map and the ground truth use exactly the pixel centres and :meth:`Camera.rays_rig` itself.
Work is done in chunks of rows (bounded memory; a 4K image or a 204-band cube is fine).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from ..camera.camera import Camera
from ..errors import InputError
from ..progress import Reporter, ensure_reporter
from ..data.recording import Recording
from ..camera.rig import Rig
from .scene import MAT_GROUND, Scene
from .textures import NIR_850, RGB_ALBEDO, Appearance, endmember_spectra

#: rays cast per chunk (bounds memory: ~100 bytes per ray in flight)
RAY_CHUNK = 1 << 19
#: supersample (2x2) cameras up to this many pixels; larger ones (4K) are rendered 1x1
SUPERSAMPLE_MAX_PX = 2_100_000
#: active-infrared scale: digital numbers for reflectance 1 at 1 m, lit head-on
IR_GAIN = 2600.0
#: image noise (``sensor_noise=True``), Gaussian sigma: infrared relative + absolute DN, RGB in
#: 8-bit DN, thermal in K (NETD), hyperspectral in reflectance
SENSOR_NOISE = {"infrared_rel": 0.015, "infrared_abs": 3.0, "rgb": 1.2, "thermal": 0.04, "hyperspectral": 0.002}


# ---------------------------------------------------------------------- images
def _srgb_curve(lin: np.ndarray) -> np.ndarray:
    lin = np.clip(lin, 0.0, 1.0)
    return np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * np.power(lin, 1 / 2.4) - 0.055)


#: sRGB encoding as a table over 16-bit linear values (a 4K image has 25 M values to encode)
_SRGB_LUT = _srgb_curve(np.arange(65536) / 65535.0).astype(np.float32)


def _srgb_encode(lin: np.ndarray) -> np.ndarray:
    """Linear [0, 1] -> sRGB-encoded [0, 1], float32, same shape."""
    idx = np.clip(lin * np.float32(65535.0) + np.float32(0.5), 0, 65535).astype(np.uint16)
    return _SRGB_LUT[idx]


def _channels(cam: Camera) -> int:
    if cam.modality == "rgb":
        return 3
    if cam.modality == "hyperspectral":
        return len(cam.extra.get("bands", []))
    return 1


def _render_rays(cam: Camera, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Like :meth:`Camera.rays_rig` but with 10 undistortion iterations instead of 50: for image
    synthesis an error of < 1e-5 px is plenty (the ground truth uses the exact rays)."""
    xy = cv2.undistortPoints(np.ascontiguousarray(uv.reshape(-1, 1, 2)), cam.K, cam.dist, None, np.eye(3),
                             criteria=(cv2.TERM_CRITERIA_COUNT, 10, 0.0)).reshape(-1, 2)
    d = xy @ cam.R_cam_rig[:2] + cam.R_cam_rig[2]  # R_rig_cam @ (x, y, 1), as rows
    d /= np.sqrt(np.einsum("ij,ij->i", d, d))[:, None]
    return cam.center_rig, d


def _render_rays_grid(cam: Camera, r0: int, r1: int, offs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rays through sub-pixel samples ``offs`` (S, 2) of every pixel of rows ``r0:r1``, in the
    order (pixel, sample). The distortion is inverted once per pixel (on a grid one pixel wider
    than the rows) and the samples follow from a second-order Taylor expansion of that smooth map:
    4x fewer undistortions, with errors far below 1e-4 px for offsets of a quarter pixel."""
    if len(offs) == 1 and not np.any(offs):
        v, u = np.mgrid[r0:r1, 0:cam.width]
        return _render_rays(cam, np.stack([u.ravel(), v.ravel()], axis=1).astype(np.float64))
    v, u = np.mgrid[r0 - 1:r1 + 1, -1:cam.width + 1]
    uv = np.stack([u.ravel(), v.ravel()], axis=1).astype(np.float64)
    G = cv2.undistortPoints(np.ascontiguousarray(uv.reshape(-1, 1, 2)), cam.K, cam.dist, None, np.eye(3),
                            criteria=(cv2.TERM_CRITERIA_COUNT, 10, 0.0)).reshape(r1 - r0 + 2, cam.width + 2, 2)
    c = G[1:-1, 1:-1]
    fu = 0.5 * (G[1:-1, 2:] - G[1:-1, :-2])
    fv = 0.5 * (G[2:, 1:-1] - G[:-2, 1:-1])
    fuu = G[1:-1, 2:] - 2 * c + G[1:-1, :-2]
    fvv = G[2:, 1:-1] - 2 * c + G[:-2, 1:-1]
    fuv = 0.25 * (G[2:, 2:] - G[2:, :-2] - G[:-2, 2:] + G[:-2, :-2])
    du, dv = offs[:, 0], offs[:, 1]
    xy = (c[:, :, None] + fu[:, :, None] * du[:, None] + fv[:, :, None] * dv[:, None]
          + 0.5 * fuu[:, :, None] * (du**2)[:, None] + 0.5 * fvv[:, :, None] * (dv**2)[:, None]
          + fuv[:, :, None] * (du * dv)[:, None])  # (rows, W, S, 2)
    xy = xy.reshape(-1, 2)
    d = xy @ cam.R_cam_rig[:2] + cam.R_cam_rig[2]
    d /= np.sqrt(np.einsum("ij,ij->i", d, d))[:, None]
    return cam.center_rig, d


def _render_camera(cam: Camera, scene: Scene, app: Appearance, supersample: int | None,
                   rng: np.random.Generator | None, progress: Reporter) -> np.ndarray:
    """Image of one camera: (H, W) or (H, W, C) in the modality's dtype and units."""
    H, W = cam.shape
    ss = supersample or (2 if H * W <= SUPERSAMPLE_MAX_PX else 1)
    mod = cam.modality
    spectra = None
    if mod == "hyperspectral":
        bands = np.asarray(cam.extra.get("bands", []), dtype=np.float64)
        if bands.size == 0:
            raise InputError(f"hyperspectral camera '{cam.name}' has no \"bands\" (wavelengths in nm)")
        spectra = endmember_spectra(bands)  # (E, B)
    C = _channels(cam)
    # linear quantity per pixel before the modality's final encoding
    out = np.empty((H, W, C), dtype=np.float32)

    off = (np.arange(ss) + 0.5) / ss - 0.5
    du, dv = np.meshgrid(off, off)
    offs = np.stack([du.ravel(), dv.ravel()], axis=1)  # (ss*ss, 2)
    # bound both rays in flight and the expanded spectral chunk (pixels x bands)
    rows = max(1, min(H, RAY_CHUNK // (W * ss * ss), (1 << 24) // max(1, W * C)))
    for r0 in range(0, H, rows):
        r1 = min(H, r0 + rows)
        npx = (r1 - r0) * W
        o, d = _render_rays_grid(cam, r0, r1, offs)
        t, prim, bary = scene.cast(o, d)
        hit = prim >= 0
        s = scene.surface(prim[hit], bary[hit], points=False)
        # for appearance, the float32 ray distance is exact enough (~0.1 um)
        s["points"] = o + t[hit, None] * d[hit]
        n = len(d)
        if mod == "thermal":
            val = np.full((n, 1), np.nan, np.float32)
            val[hit, 0] = app.temperature(s["points"], s["material"], s["uv"])
        else:
            A = np.zeros((n, RGB_ALBEDO.shape[0]), np.float32)
            Ah = app.abundance(s["points"], s["material"], s["uv"])
            if mod == "infrared":
                # lit by the camera's own emitter: cosine to the viewing ray, inverse square distance
                rel = s["points"] - o
                dist2 = np.einsum("ij,ij->i", rel, rel)
                cos = np.abs(np.einsum("ij,ij->i", s["normal"], d[hit]))
                A[hit] = Ah * ((0.25 + 0.75 * cos) / dist2).astype(np.float32)[:, None]
            else:
                A[hit] = Ah * app.shading(s["normal"]).astype(np.float32)[:, None]
            val = A
        # average the supersamples (every quantity here is linear in radiance / temperature)
        val = val.reshape(npx, ss * ss, -1).mean(axis=1)
        if mod == "infrared":
            res = IR_GAIN * (val @ NIR_850.astype(np.float32))[:, None]
        elif mod == "rgb":
            res = val @ RGB_ALBEDO.astype(np.float32)
        elif mod == "hyperspectral":
            res = val @ spectra
        elif mod == "thermal":
            res = val
        else:  # any other modality: a grey-level reflectance image
            res = (val @ RGB_ALBEDO.astype(np.float32)).mean(axis=1, keepdims=True)
        out[r0:r1] = res.reshape(r1 - r0, W, -1)
        progress(r1 / H, f"rendering {cam.name}")

    blur = float(cam.extra.get("blur_px", 0.0) or 0.0)
    if blur > 0:  # optical blur (e.g. a thermal lens): Gaussian PSF, sigma in the camera's pixels
        for c0 in range(0, out.shape[2], 4):
            blk = np.ascontiguousarray(out[..., c0:c0 + 4])
            res_b = cv2.GaussianBlur(blk, (0, 0), blur, borderType=cv2.BORDER_REPLICATE)
            out[..., c0:c0 + 4] = res_b.reshape(blk.shape)

    # sensor noise and encoding
    if mod == "infrared":
        img = out[..., 0]
        if rng is not None:
            img = (img * (1 + SENSOR_NOISE["infrared_rel"] * rng.standard_normal(img.shape, dtype=np.float32))
                   + SENSOR_NOISE["infrared_abs"] * rng.standard_normal(img.shape, dtype=np.float32))
        return np.clip(np.round(img), 0, 65535).astype(np.uint16)
    if mod == "rgb":
        img = 255.0 * _srgb_encode(out)
        if rng is not None:
            img = img + SENSOR_NOISE["rgb"] * rng.standard_normal(img.shape, dtype=np.float32)
        return np.clip(np.round(img), 0, 255).astype(np.uint8)
    if mod == "thermal":
        img = out[..., 0]
        if rng is not None:
            img = img + SENSOR_NOISE["thermal"] * rng.standard_normal(img.shape, dtype=np.float32)
        return img.astype(np.float32)
    if mod == "hyperspectral":
        if rng is not None:
            for r0 in range(0, H, 32):  # in place, row blocks: no second cube in memory
                blk = out[r0:r0 + 32]
                blk += SENSOR_NOISE["hyperspectral"] * rng.standard_normal(blk.shape, dtype=np.float32)
        return out
    return out[..., 0]


def render_depth(rig: Rig, scene: Scene, depth_noise: tuple[float, float] = (0.0, 0.0),
                 rng: np.random.Generator | None = None) -> np.ndarray:
    """Depth map (H, W) uint16 of the depth camera in units of ``rig.depth_scale``: z along the
    optical axis of the first hit through each (distorted) pixel centre, 0 where nothing is hit.
    ``depth_noise = (sigma_abs_m, sigma_rel)``: Gaussian noise of sigma ``abs + rel * z`` added before
    quantisation."""
    cam = rig.depth()
    o, d = cam.rays_rig()
    _t, prim, _bary = scene.cast(o, d)
    hit = prim >= 0
    z = np.zeros(len(d))
    z[hit] = cam.to_cam(scene.refine(o, d[hit], prim[hit]))[:, 2]
    sa, sr = depth_noise
    if (sa > 0 or sr > 0) and rng is not None:
        z[hit] += (sa + sr * z[hit]) * rng.standard_normal(int(hit.sum()))
    q = np.round(z / rig.depth_scale)
    q[~hit | (q < 0)] = 0
    return np.clip(q, 0, 65535).astype(np.uint16).reshape(cam.shape)


#: ToF artefacts of :func:`render_tof_depth`: footprint samples per axis, and the incidence angles
#: (between the viewing ray and the surface normal) over which the return fades out into holes
TOF_FOOTPRINT_SS = 4
TOF_HOLE_ANGLES_DEG = (70.0, 82.0)


def render_tof_depth(rig: Rig, scene: Scene, depth_noise: tuple[float, float] = (0.001, 0.001),
                     rng: np.random.Generator | None = None, footprint_ss: int = TOF_FOOTPRINT_SS,
                     hole_angles_deg: tuple[float, float] = TOF_HOLE_ANGLES_DEG) -> np.ndarray:
    """Depth map (H, W) uint16 (units of ``rig.depth_scale``) with time-of-flight artefacts:

    * **footprint mixing (flying pixels)**: each pixel integrates its whole footprint
      (``footprint_ss`` x ``footprint_ss`` samples over the pixel's square); where it straddles
      two surfaces (a leaf and the ground) it reports the mean z of what it sees, a depth in
      between that belongs to neither;
    * **holes on steep surfaces**: the return fades with the incidence angle at the pixel
      centre's hit; beyond ``hole_angles_deg[0]`` a pixel is dropped (0) with a probability
      rising linearly to 1 at ``hole_angles_deg[1]``;
    * **noise**: Gaussian, sigma ``abs + rel * z`` (``depth_noise``), then quantisation.

    ``rng`` None: no noise and deterministic holes (dropped beyond the middle angle).
    """
    cam = rig.depth()
    H, W = cam.shape
    ss = max(1, int(footprint_ss))
    off = (np.arange(ss) + 0.5) / ss - 0.5
    du, dv = np.meshgrid(off, off)
    offs = np.stack([du.ravel(), dv.ravel()], axis=1)
    axis = cam.R_cam_rig[2]  # optical axis in the rig frame: z_cam = axis . (X - C)
    z = np.zeros(H * W)
    cos_in = np.ones(H * W)
    rows = max(1, RAY_CHUNK // (W * ss * ss))
    for r0 in range(0, H, rows):
        r1 = min(H, r0 + rows)
        o, d = _render_rays_grid(cam, r0, r1, offs)
        t, prim, _bary = scene.cast(o, d)
        zs = (t[:, None] * d @ axis[:, None])[:, 0].reshape(-1, ss * ss)  # inf where no hit
        hit = np.isfinite(zs)
        with np.errstate(invalid="ignore"):
            zm = np.where(hit, zs, 0).sum(axis=1) / np.maximum(hit.sum(axis=1), 1)
        zm[hit.sum(axis=1) < (ss * ss + 1) // 2] = 0  # mostly nothing: no return
        z[r0 * W:r1 * W] = zm
        # incidence at the centre of the footprint (the nearest sample to it)
        oc, dc = _render_rays(cam, np.stack(np.meshgrid(np.arange(W), np.arange(r0, r1)), -1).reshape(-1, 2)
                              .astype(np.float64))
        _tc, pc, bc = scene.cast(oc, dc)
        ok = pc >= 0
        n = scene.surface(pc[ok], bc[ok], points=False)["normal"]
        ci = np.ones(len(dc))
        ci[ok] = np.abs(np.einsum("ij,ij->i", n, dc[ok]))
        cos_in[r0 * W:r1 * W] = ci
    ang = np.degrees(np.arccos(np.clip(cos_in, 0, 1)))
    a0, a1 = hole_angles_deg
    p_drop = np.clip((ang - a0) / max(a1 - a0, 1e-9), 0, 1)
    drop = (rng.random(len(z)) < p_drop) if rng is not None else p_drop >= 0.5
    hit = z > 0
    sa, sr = depth_noise
    if (sa > 0 or sr > 0) and rng is not None:
        z[hit] += (sa + sr * z[hit]) * rng.standard_normal(int(hit.sum()))
    q = np.round(z / rig.depth_scale)
    q[~hit | drop | (q < 0)] = 0
    return np.clip(q, 0, 65535).astype(np.uint16).reshape(H, W)


def render_recording(rig: Rig, scene: Scene, depth_noise: tuple[float, float] = (0.0, 0.0), seed: int = 0,
                     progress: Reporter | None = None, *, sensor_noise: bool = True,
                     supersample: int | None = None, tof: bool = False) -> Recording:
    """Render the depth map and every camera's image of ``scene`` as seen by ``rig``.

    Images: infrared uint16 (active illumination, leaves bright), RGB uint8, thermal float32 degC,
    hyperspectral float32 reflectance (H, W, B), other modalities float32 grey. ``sensor_noise``
    adds mild, seeded image noise (never to the depth: that is ``depth_noise``). ``supersample``
    forces the per-axis supersampling (default: 2 up to ~2 Mpx, else 1). ``tof``: the depth map
    gets time-of-flight artefacts (:func:`render_tof_depth`: flying pixels by footprint mixing,
    holes on steep surfaces, ``depth_noise``). A camera with ``"blur_px"`` in its extra keys is
    blurred optically (Gaussian, that sigma in its pixels) before its sensor noise.
    Returns an in-memory :class:`Recording` (``folder`` None).
    """
    progress = ensure_reporter(progress)
    app = Appearance(scene)
    images: dict[str, np.ndarray] = {}
    weights = np.array([c.width * c.height * max(1, _channels(c)) ** 0.3 for c in rig.cameras], dtype=float)
    edges = np.concatenate([[0.05], 0.05 + 0.95 * np.cumsum(weights) / weights.sum()])
    with progress.stage("depth", 0.0, 0.05):
        drng = np.random.default_rng([seed, 0])
        depth = render_tof_depth(rig, scene, depth_noise, drng) if tof else render_depth(rig, scene, depth_noise, drng)
    for i, cam in enumerate(rig.cameras):
        with progress.stage(f"render {cam.name}", edges[i]):
            crng = np.random.default_rng([seed, 2, i]) if sensor_noise else None
            images[cam.name] = _render_camera(cam, scene, app, supersample, crng, progress.sub(edges[i], edges[i + 1]))
    return Recording(None, depth, images, extra={"synthetic": {"seed": seed, "depth_noise": list(depth_noise),
                                                               "tof_artefacts": bool(tof)}})


# ---------------------------------------------------------------------- ground truth
@dataclass
class GroundTruth:
    """True registration of every target pixel; arrays in the target's pixel grid (H, W).

    ``points_rig`` (H, W, 3) float64 first hit of the pixel-centre ray in the true scene (NaN if
    none); ``material`` (H, W) int (-1 none); ``object`` (H, W) bool: the hit is pot, soil, stem or
    leaf (not ground). Per source camera: ``uv[src]`` (H, W, 2) the true point's distorted pixel
    coordinates in the source (NaN if none / behind), ``in_image[src]`` (H, W) bool,
    ``visible[src]`` (H, W) bool: the segment from the source's centre to the point hits nothing
    more than ``visibility_tol_m`` before the point, ``matchable[src] = object & in_image & visible``.
    """

    target: str
    points_rig: np.ndarray
    material: np.ndarray
    object: np.ndarray
    uv: dict[str, np.ndarray] = field(default_factory=dict)
    in_image: dict[str, np.ndarray] = field(default_factory=dict)
    visible: dict[str, np.ndarray] = field(default_factory=dict)
    matchable: dict[str, np.ndarray] = field(default_factory=dict)
    visibility_tol_m: float = 1e-3

    @property
    def sources(self) -> list[str]:
        return list(self.uv)

    @property
    def shape(self) -> tuple[int, int]:
        return self.material.shape  # type: ignore[return-value]

    def occluded(self, src: str) -> np.ndarray:
        """Object pixels whose point lies in the source image but is hidden from the source (H, W)."""
        return self.object & self.in_image[src] & ~self.visible[src]

    def save(self, path: str | Path) -> None:
        """Write a compressed ``.npz`` (keys ``uv/<src>``, ``visible/<src>``, ...), atomically."""
        from ..io.imageio import atomic_path

        arrays: dict[str, np.ndarray] = {
            "target": np.array(self.target), "points_rig": self.points_rig, "material": self.material,
            "object": self.object, "visibility_tol_m": np.array(self.visibility_tol_m),
        }
        for key in ("uv", "in_image", "visible", "matchable"):
            for src, a in getattr(self, key).items():
                arrays[f"{key}/{src}"] = a
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as f:
                np.savez_compressed(f, **arrays)

    @classmethod
    def load(cls, path: str | Path) -> "GroundTruth":
        path = Path(path)
        if not path.is_file():
            raise InputError("ground-truth file not found", path)
        with np.load(path, allow_pickle=False) as z:
            gt = cls(str(z["target"]), z["points_rig"], z["material"], z["object"],
                     visibility_tol_m=float(z["visibility_tol_m"]))
            for k in z.files:
                if "/" in k:
                    key, src = k.split("/", 1)
                    getattr(gt, key)[src] = z[k]
        return gt


def ground_truth(rig: Rig, scene: Scene, target: str, visibility_tol_m: float = 1e-3,
                 progress: Reporter | None = None, sources: list[str] | None = None) -> GroundTruth:
    """Ground truth for registering the other cameras of ``rig`` into ``target`` (see
    :class:`GroundTruth`). Target rays go through the distorted pixel centres; hit points are
    exact (float64 ray-plane intersection with the triangle Embree found).
    ``sources``: camera names to compute (default: every camera except the target)."""
    progress = ensure_reporter(progress)
    cam = rig.camera(target)
    H, W = cam.shape
    N = H * W
    P = np.full((N, 3), np.nan)
    mat = np.full(N, -1, dtype=np.int32)
    px = cam.pixel_grid()
    for a in range(0, N, RAY_CHUNK):
        b = min(N, a + RAY_CHUNK)
        o, d = cam.rays_rig(px[a:b])
        _t, prim, _bary = scene.cast(o, d)
        hit = prim >= 0
        idx = np.arange(a, b)[hit]
        P[idx] = scene.refine(o, d[hit], prim[hit])
        mat[idx] = scene.material[prim[hit]]
        progress(0.3 * b / N, f"ground truth: {target} rays")
    hit = mat >= 0
    gt = GroundTruth(target, P.reshape(H, W, 3), mat.reshape(H, W), (mat > MAT_GROUND).reshape(H, W),
                     visibility_tol_m=visibility_tol_m)
    sources = [rig.camera(n) for n in sources] if sources is not None else [c for c in rig.cameras if c.name != target]
    Ph = P[hit]
    for i, src in enumerate(sources):
        uv = np.full((N, 2), np.nan)
        inimg = np.zeros(N, bool)
        vis = np.zeros(N, bool)
        uvh, z = src.project(Ph)
        uv[hit] = uvh
        inimg[hit] = (z > 0) & src.in_image(uvh)
        C = src.center_rig
        vec = Ph - C
        D = np.linalg.norm(vec, axis=1)
        visible_h = np.zeros(len(Ph), bool)
        for a in range(0, len(Ph), RAY_CHUNK):
            b = min(len(Ph), a + RAY_CHUNK)
            t, _p, _b = scene.cast(C, vec[a:b] / D[a:b, None])
            visible_h[a:b] = t >= D[a:b] - visibility_tol_m
        vis[hit] = visible_h
        gt.uv[src.name] = uv.reshape(H, W, 2)
        gt.in_image[src.name] = inimg.reshape(H, W)
        gt.visible[src.name] = vis.reshape(H, W)
        gt.matchable[src.name] = gt.object & gt.in_image[src.name] & gt.visible[src.name]
        progress(0.3 + 0.7 * (i + 1) / len(sources), f"ground truth: {src.name}")
    progress(1.0, "ground truth")
    return gt


def observable_views(rig: Rig, scene: Scene, gt: GroundTruth, tol_m: float = 0.002, step_m: float = 0.002,
                     supersample: int = 4) -> dict[str, np.ndarray]:
    """Which truly matchable pixels could *any* registration from this rig's depth alone certify?

    Per source of ``gt`` (whose target is any camera), (H, W) bool: the pixel is matchable
    (``gt.matchable``) and the whole segment from its true point to the source camera's centre
    (beyond ``tol_m`` from the point) lies in space the depth camera observes, i.e. in front of
    the first true surface along the depth camera's line of sight (within ``tol_m``). A point
    whose view of the source passes through space hidden from the depth camera -- under a leaf,
    behind a stem -- cannot be told from an occluded one by depth alone: this is the upper bound
    on P1 coverage for a method that calls P1 only what the depth shows to be clear.

    The depth camera is taken as ideal (exact, infinitely fine): a regular grid of its viewing
    directions ``supersample`` times finer than its pixels is cast into the true scene once;
    segment points every ``step_m`` are looked up at the nearest direction. Points outside its
    field of view count as hidden. ``gt.points_rig`` are the true points.
    """
    dcam = rig.depth()
    H, W = dcam.shape
    border = np.concatenate([np.stack([np.arange(W), np.zeros(W)], 1), np.stack([np.arange(W), np.full(W, H - 1)], 1),
                             np.stack([np.zeros(H), np.arange(H)], 1), np.stack([np.full(H, W - 1), np.arange(H)], 1)])
    xy = dcam.undistort_normalized(border.astype(np.float64))
    d = 1.0 / (dcam.K[0, 0] * supersample)
    (x0, y0), (x1, y1) = xy.min(axis=0), xy.max(axis=0)
    xs, ys = np.arange(x0, x1 + d, d), np.arange(y0, y1 + d, d)
    gx, gy = np.meshgrid(xs, ys)
    dc = np.stack([gx.ravel(), gy.ravel(), np.ones(gx.size)], axis=1)
    norm = np.linalg.norm(dc, axis=1)
    zmap = np.empty(len(dc))
    for a in range(0, len(dc), 1 << 20):
        dr = (dc[a:a + (1 << 20)] @ dcam.R_cam_rig) / norm[a:a + (1 << 20), None]  # rig-frame unit rays
        t, _p, _b = scene.cast(dcam.center_rig, dr)
        zmap[a:a + (1 << 20)] = t / norm[a:a + (1 << 20)]  # distance along the ray -> camera-frame z
    zmap = zmap.reshape(gx.shape)
    z_top = float(np.min(zmap)) - tol_m  # nothing is hidden in front of the nearest surface
    out: dict[str, np.ndarray] = {}
    for name, match in gt.matchable.items():
        X = gt.points_rig[match].astype(np.float64)
        S = rig.camera(name).center_rig
        v = S - X
        L = np.linalg.norm(v, axis=1)
        u = v / L[:, None]
        ok = np.ones(len(X), dtype=bool)
        s = tol_m
        while True:
            act = np.flatnonzero(ok & (s < L))
            if len(act) == 0:
                break
            Yc = dcam.to_cam(X[act] + u[act] * s)
            z = Yc[:, 2]
            near = z < z_top
            with np.errstate(divide="ignore", invalid="ignore"):
                i = np.rint((Yc[:, 1] / z - y0) / d)
                j = np.rint((Yc[:, 0] / z - x0) / d)
            inside = (z > 0) & (i >= 0) & (i < len(ys)) & (j >= 0) & (j < len(xs))
            zs = np.full(len(act), -np.inf)
            zs[inside] = zmap[i[inside].astype(np.int64), j[inside].astype(np.int64)]
            hidden = ~near & (zs < z - tol_m)
            ok[act[hidden]] = False
            done = near & ~hidden
            ok_act = act[done]  # above every surface: the rest of the segment is observed
            L[ok_act] = 0.0
            s += step_m
        m = np.zeros(match.shape, dtype=bool)
        m[match] = ok
        out[name] = m
    return out
