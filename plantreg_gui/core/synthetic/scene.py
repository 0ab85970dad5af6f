"""True geometry of the synthetic plant scene: a finely tessellated triangle mesh.

The mesh *is* the true surface: leaves are tessellated with edges of at most ~1.5 mm, so the
difference between the tessellation and the analytic blade is far below a pixel of any camera
of the demo rig. Everything is in the rig frame (= the depth camera's frame: x right, y down,
z forward, i.e. towards the ground).

Material ids per triangle:

=========  =========================================
0          ground plane (z = ``ground_z``)
1          pot (outer wall, rim, inner wall)
2          soil (top of the pot's filling)
3          stems (main stem and petioles)
10 + k     leaf k
=========  =========================================

Every triangle vertex also carries surface coordinates ``vertex_uv`` (V, 2) in metres, used by
the textures: leaves (distance along the midrib, signed distance across it), pot (arc length
around the axis, height), others (0, 0). Textures are evaluated at the exact hit point by
barycentric interpolation, so they are functions of the surface point, never of an image.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import open3d as o3d

MAT_GROUND, MAT_POT, MAT_SOIL, MAT_STEM, MAT_LEAF0 = 0, 1, 2, 3, 10

#: Ground plane of the demo in the rig frame (the camera looks straight down onto it).
GROUND_Z = 1.20
#: Grid spacing on curved parts (leaves, pot, soil), metres: quad diagonals (the longest triangle edges) stay under 2 mm.
MAX_EDGE = 0.00125


@dataclass
class Leaf:
    """Parameters of one leaf blade (rig frame, metres, degrees)."""

    index: int
    base: np.ndarray          # (3,) where the blade starts (end of the petiole)
    azimuth_deg: float        # direction of the midrib seen from above
    incline_deg: float        # angle of the blade's start to the image plane (0 = flat)
    rising: bool              # True: the blade rises towards the camera, False: it dips
    length: float
    width: float
    droop: float              # bend of the midrib: the tip sinks by this much (m)
    cup: float                # cross curvature (1/m): the margins rise by cup * (half width)^2
    roll_deg: float           # twist of the blade about the midrib
    tone: float               # 0..1, per-leaf colour variation (pale <-> dark)

    def to_dict(self) -> dict[str, Any]:
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in self.__dict__.items()}


@dataclass
class Scene:
    """The true scene: mesh (vertices (V, 3), triangles (T, 3)), per-triangle ``material`` (T,),
    per-vertex ``vertex_uv`` (V, 2) surface coordinates and ``vertex_normals`` (V, 3).

    ``ground_z`` is the ground plane's z (rig frame). ``cast`` intersects rays with the mesh
    using Open3D's RaycastingScene (Embree), built once and cached.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    material: np.ndarray
    vertex_uv: np.ndarray
    vertex_normals: np.ndarray
    ground_z: float
    leaves: list[Leaf]
    seed: int
    params: dict[str, Any] = field(default_factory=dict)
    _rc: Any = field(default=None, repr=False, compare=False)

    # ------------------------------------------------------------------ views
    @property
    def n_leaves(self) -> int:
        return len(self.leaves)

    @property
    def mesh(self) -> o3d.geometry.TriangleMesh:
        """The true surface as an Open3D legacy triangle mesh (materials in ``self.material``)."""
        m = o3d.geometry.TriangleMesh(
            o3d.utility.Vector3dVector(self.vertices), o3d.utility.Vector3iVector(self.triangles)
        )
        m.vertex_normals = o3d.utility.Vector3dVector(self.vertex_normals)
        return m

    def raycasting_scene(self) -> o3d.t.geometry.RaycastingScene:
        if self._rc is None:
            rc = o3d.t.geometry.RaycastingScene()
            rc.add_triangles(
                o3d.core.Tensor(self.vertices.astype(np.float32)),
                o3d.core.Tensor(self.triangles.astype(np.uint32)),
            )
            self._rc = rc
        return self._rc

    # ------------------------------------------------------------------ ray casting
    def cast(self, origins: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """First hits of rays. ``origins`` (3,) or (N, 3), ``dirs`` (N, 3) unit vectors (rig frame).

        Returns ``t`` (N,) float64 distance along the ray (inf if no hit), ``prim`` (N,) int64
        triangle index (-1 if none), ``bary`` (N, 2) float64 barycentric (u, v) with
        ``hit = (1-u-v) * V0 + u * V1 + v * V2``.
        """
        dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
        o = np.broadcast_to(np.asarray(origins, dtype=np.float64), dirs.shape)
        rays = np.concatenate([o, dirs], axis=1).astype(np.float32)
        n = len(rays)
        t, prim, bary = np.empty(n), np.empty(n, np.int64), np.empty((n, 2))
        step = 1 << 15  # Open3D holds the GIL for a whole call: short calls keep a GUI responsive
        for a in range(0, n, step):
            ans = self.raycasting_scene().cast_rays(o3d.core.Tensor(rays[a:a + step]))
            t[a:a + step] = ans["t_hit"].numpy()
            prim[a:a + step] = ans["primitive_ids"].numpy()
            bary[a:a + step] = ans["primitive_uvs"].numpy()
        miss = ~np.isfinite(t)
        prim[miss] = -1
        return t, prim, bary

    def surface(self, prim: np.ndarray, bary: np.ndarray, points: bool = True) -> dict[str, np.ndarray]:
        """Surface attributes at hits (``prim`` (N,) >= 0): exact ``points`` (N, 3) float64 on the
        tessellated surface (skipped if ``points`` is False), ``material`` (N,), unit ``normal``
        (N, 3) float32 (interpolated, so shading is smooth), surface coordinates ``uv`` (N, 2) float32."""
        tri = self.triangles[prim]
        mat = self.material[prim]
        # the ground is flat and its texture uses 3D points only: interpolate the rest
        curved = np.flatnonzero(mat != MAT_GROUND)
        n = np.empty((len(prim), 3), np.float32)
        n[:] = self._normals32[self.triangles[np.argmax(self.material == MAT_GROUND), 0]]
        uv = np.zeros((len(prim), 2), np.float32)
        if len(curved):
            tc = tri[curved]
            u = bary[curved, 0:1].astype(np.float32)
            v = bary[curved, 1:2].astype(np.float32)

            def interp(a: np.ndarray) -> np.ndarray:
                a0, a1, a2 = a[tc[:, 0]], a[tc[:, 1]], a[tc[:, 2]]
                return a0 + u * (a1 - a0) + v * (a2 - a0)

            nc = interp(self._normals32)
            n[curved] = nc / np.maximum(np.linalg.norm(nc, axis=1, keepdims=True), 1e-12)
            uv[curved] = interp(self._uv32)
        out = {"material": mat, "normal": n, "uv": uv}
        if points:
            V = self.vertices
            p0 = V[tri[:, 0]]
            out["points"] = p0 + bary[:, 0:1] * (V[tri[:, 1]] - p0) + bary[:, 1:2] * (V[tri[:, 2]] - p0)
        return out

    def refine(self, origins: np.ndarray, dirs: np.ndarray, prim: np.ndarray) -> np.ndarray:
        """Exact hit points (N, 3) float64: the rays (float64) intersected with the planes of the
        triangles ``prim`` (N,) >= 0 that Embree found (in float32). The point lies on the ray to
        ~1e-12 m and on the triangle's plane, where the float32 result is off by up to ~1e-6 m on
        the large ground triangles."""
        dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
        o = np.broadcast_to(np.asarray(origins, dtype=np.float64), dirs.shape)
        tri = self.triangles[prim]
        v0 = self.vertices[tri[:, 0]]
        n = np.cross(self.vertices[tri[:, 1]] - v0, self.vertices[tri[:, 2]] - v0)
        t = np.einsum("ij,ij->i", n, v0 - o) / np.einsum("ij,ij->i", n, dirs)
        return o + t[:, None] * dirs

    @property
    def _normals32(self) -> np.ndarray:
        if "_n32" not in self.__dict__:
            self.__dict__["_n32"] = self.vertex_normals.astype(np.float32)
        return self.__dict__["_n32"]

    @property
    def _uv32(self) -> np.ndarray:
        if "_uv32c" not in self.__dict__:
            self.__dict__["_uv32c"] = self.vertex_uv.astype(np.float32)
        return self.__dict__["_uv32c"]

    def leaf_ids(self) -> list[int]:
        return [MAT_LEAF0 + lf.index for lf in self.leaves]


# ---------------------------------------------------------------------- tessellation helpers
def _grid_triangles(nu: int, nv: int, closed_u: bool = False) -> np.ndarray:
    """Triangles of a (nu x nv) vertex grid (index = i * nv + j), alternating diagonals.
    ``closed_u`` joins the last row in u to the first (surfaces of revolution)."""
    iu = nu if closed_u else nu - 1
    i, j = np.meshgrid(np.arange(iu), np.arange(nv - 1), indexing="ij")
    i, j = i.ravel(), j.ravel()
    i1 = (i + 1) % nu
    a, b, c, d = i * nv + j, i1 * nv + j, i1 * nv + j + 1, i * nv + j + 1
    flip = (i + j) % 2 == 1
    t1 = np.where(flip[:, None], np.stack([a, b, d], 1), np.stack([a, b, c], 1))
    t2 = np.where(flip[:, None], np.stack([b, c, d], 1), np.stack([a, c, d], 1))
    return np.concatenate([t1, t2]).astype(np.int64)


def _resample_polyline(p: np.ndarray, max_step: float) -> np.ndarray:
    """Points (N, D) of a polyline, resampled so that no step exceeds ``max_step`` (corners kept)."""
    out = [p[:1]]
    for a, b in zip(p[:-1], p[1:]):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / max_step)))
        s = np.linspace(0, 1, n + 1)[1:, None]
        out.append(a + s * (b - a))
    return np.concatenate(out)


class _MeshBuilder:
    def __init__(self) -> None:
        self.v: list[np.ndarray] = []
        self.t: list[np.ndarray] = []
        self.m: list[np.ndarray] = []
        self.uv: list[np.ndarray] = []
        self.n = 0

    def add(self, verts: np.ndarray, tris: np.ndarray, material: int, uv: np.ndarray | None = None) -> None:
        self.v.append(np.asarray(verts, dtype=np.float64))
        self.t.append(np.asarray(tris, dtype=np.int64) + self.n)
        self.m.append(np.full(len(tris), material, dtype=np.int32))
        self.uv.append(np.zeros((len(verts), 2)) if uv is None else np.asarray(uv, dtype=np.float64))
        self.n += len(verts)

    def build(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        return (np.concatenate(self.v), np.concatenate(self.t), np.concatenate(self.m), np.concatenate(self.uv))


def _revolve(profile_rz: np.ndarray, center_xy: np.ndarray, n_theta: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Surface of revolution about a vertical axis through ``center_xy``; ``profile_rz`` (P, 2)."""
    th = np.linspace(0, 2 * np.pi, n_theta, endpoint=False)
    r, z = profile_rz[:, 0], profile_rz[:, 1]
    X = center_xy[0] + np.cos(th)[:, None] * r[None]
    Y = center_xy[1] + np.sin(th)[:, None] * r[None]
    Z = np.broadcast_to(z[None], X.shape)
    verts = np.stack([X, Y, Z], axis=-1).reshape(-1, 3)
    s = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(profile_rz, axis=0), axis=1))])
    uv = np.stack([np.broadcast_to((th * r.max())[:, None], X.shape), np.broadcast_to(s[None], X.shape)], -1)
    return verts, _grid_triangles(n_theta, len(profile_rz), closed_u=True), uv.reshape(-1, 2)


def _tube(a: np.ndarray, b: np.ndarray, radius: float, n_around: int = 16, max_step: float = 0.003
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Open cylinder from point ``a`` to ``b`` (stems)."""
    axis = b - a
    L = float(np.linalg.norm(axis))
    w = axis / L
    u = np.cross(w, [1.0, 0, 0] if abs(w[0]) < 0.9 else [0, 1.0, 0])
    u /= np.linalg.norm(u)
    v = np.cross(w, u)
    th = np.linspace(0, 2 * np.pi, n_around, endpoint=False)
    s = np.linspace(0, 1, max(2, int(np.ceil(L / max_step)) + 1))
    ring = np.cos(th)[:, None] * u + np.sin(th)[:, None] * v  # (n_around, 3)
    verts = a + s[None, :, None] * axis + radius * ring[:, None, :]
    uv = np.stack(np.broadcast_arrays(th[:, None] * radius, s[None] * L), -1)
    return verts.reshape(-1, 3), _grid_triangles(n_around, len(s), closed_u=True), uv.reshape(-1, 2)


def _leaf_surface(lf: Leaf, max_edge: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tessellated blade of one leaf: vertices (V, 3), triangles (T, 3), uv (V, 2) =
    (distance along the midrib, signed distance across it) in metres."""
    phi, th, roll = np.radians([lf.azimuth_deg, lf.incline_deg, lf.roll_deg])
    up = np.array([0.0, 0.0, -1.0])  # towards the camera
    h = np.array([np.cos(phi), np.sin(phi), 0.0])
    side = np.array([-np.sin(phi), np.cos(phi), 0.0])
    a0 = np.cos(th) * h + np.sin(th) * (up if lf.rising else -up)
    n0 = np.cross(a0, side)
    n0 *= np.sign(n0 @ up) or 1.0
    # roll the blade about its start direction
    b = np.cos(roll) * side + np.sin(roll) * n0
    n = np.cos(roll) * n0 - np.sin(roll) * side

    def outline(s: np.ndarray) -> np.ndarray:
        """Half width (m) at fraction s of the length: an ellipse, widest a little before the middle."""
        sp = s ** 0.85
        hw = 0.5 * lf.width * np.sqrt(np.clip(1.0 - (2.0 * sp - 1.0) ** 2, 0.0, None))
        return np.maximum(hw, 2e-4)  # no degenerate triangles at the tips

    # rows along the blade evenly spaced along the *margin* (which is steep near the tips), so
    # that no edge, along the midrib or along the margin, exceeds max_edge
    sf = np.linspace(0.0, 1.0, 20001)
    arc = np.concatenate([[0], np.cumsum(np.hypot(np.diff(sf) * lf.length, np.diff(outline(sf))))])
    # the droop lengthens the midrib (by at most 2 * droop / length), the cup the cross section
    stretch_s = 1.0 + 2.0 * lf.droop / lf.length
    ns = int(np.ceil(stretch_s * arc[-1] / max_edge)) + 1
    s = np.interp(np.linspace(0, arc[-1], ns), arc, sf)
    nt = int(np.ceil(lf.width * np.hypot(1.0, lf.cup * lf.width) / max_edge)) + 1
    nt += nt % 2 == 0  # odd: a vertex row on the midrib
    t = np.linspace(-1.0, 1.0, nt)
    half_w = outline(s)
    S, T = np.meshgrid(s, t, indexing="ij")
    across = T * half_w[:, None]                              # (ns, nt) metres from the midrib
    mid = lf.base + (S * lf.length)[..., None] * a0 + (lf.droop * S**2)[..., None] * (-up)
    P = mid + across[..., None] * b + (lf.cup * across**2)[..., None] * n
    uv = np.stack([S * lf.length, across], axis=-1)
    return P.reshape(-1, 3), _grid_triangles(ns, nt), uv.reshape(-1, 2)


# ---------------------------------------------------------------------- the plant
def _make_leaves(rng: np.random.Generator, stem_xy: np.ndarray) -> tuple[list[Leaf], list[tuple]]:
    """Leaves spiralling up a main stem (golden angle), so that leaves several nodes apart point
    in similar directions and overlap in the top view at different heights."""
    n = int(rng.integers(8, 11))
    z_nodes = np.linspace(0.95, 0.56, n) + rng.uniform(-0.012, 0.012, n)
    az0 = rng.uniform(0, 360)
    leaves: list[Leaf] = []
    petioles: list[tuple] = []
    for k in range(n):
        az = az0 + 137.5 * k + rng.uniform(-12, 12)
        node = np.array([stem_xy[0], stem_xy[1], z_nodes[k]])
        pet_len = rng.uniform(0.035, 0.07)
        pet_rise = rng.uniform(0.005, 0.025)
        h = np.array([np.cos(np.radians(az)), np.sin(np.radians(az)), 0.0])
        base = node + pet_len * h + np.array([0, 0, -pet_rise])
        length = rng.uniform(0.15, 0.24)
        width = length * rng.uniform(0.40, 0.55)
        incline = rng.uniform(0.0, 60.0)
        rising = bool(rng.uniform() < 0.6)
        # keep the plant between 0.5 m and ~1.05 m from the camera and above the pot
        if rising and base[2] - length * np.sin(np.radians(incline)) < 0.50:
            rising = False
        if not rising and base[2] + length * np.sin(np.radians(incline)) > 1.02:
            incline = float(np.degrees(np.arcsin(max(0.0, (1.02 - base[2]) / length))))
        lf = Leaf(
            index=k, base=base, azimuth_deg=float(az % 360), incline_deg=float(incline), rising=rising,
            length=float(length), width=float(width), droop=float(rng.uniform(0.01, 0.045)),
            cup=float(rng.uniform(2.0, 8.0)), roll_deg=float(rng.uniform(-15, 15)), tone=float(rng.uniform()),
        )
        leaves.append(lf)
        petioles.append((node, base))
    return leaves, petioles


def make_plant_scene(seed: int = 0) -> Scene:
    """Build the true scene: ground plane, pot with rim and soil, a main stem with petioles and
    8-10 curved, overlapping elliptical leaves between ~0.5 and ~1.0 m from the camera.

    Deterministic for a given ``seed``. ~0.5 M triangles.
    """
    rng = np.random.default_rng(seed)
    mb = _MeshBuilder()
    gz = GROUND_Z

    # ground: a large plane (flat, so two triangles are exact); uv unused (texture uses 3D points)
    g = 5.0
    mb.add(np.array([[-g, -g, gz], [g, -g, gz], [g, g, gz], [-g, g, gz]]), np.array([[0, 1, 2], [0, 2, 3]]), MAT_GROUND)

    # pot: tapered wall, a rim that sticks out, inner wall down to the soil
    pot_xy = rng.uniform(-0.01, 0.01, 2)
    r_bot, r_top, r_rim, r_in = 0.064, 0.080, 0.088, 0.076
    z_rim_top, z_rim_bot, soil_z = gz - 0.144, gz - 0.132, gz - 0.124
    profile = np.array([
        [r_bot, gz], [r_top, z_rim_bot + 0.004], [r_rim, z_rim_bot], [r_rim, z_rim_top],
        [r_in, z_rim_top], [r_in - 0.0015, soil_z],
    ])
    profile = _resample_polyline(profile, MAX_EDGE * 1.3)
    n_theta = int(np.ceil(2 * np.pi * r_rim / MAX_EDGE))
    v, t, uv = _revolve(profile, pot_xy, n_theta)
    mb.add(v, t, MAT_POT, uv)

    # soil: a gently domed disc inside the inner wall
    r_soil = r_in - 0.0015
    radii = np.linspace(0.0, r_soil, int(np.ceil(r_soil / MAX_EDGE)) + 1)
    prof = np.stack([radii, soil_z - 0.004 * (1 - (radii / r_soil) ** 2)], axis=1)
    prof[0, 0] = 1e-5  # a tiny hole at the centre instead of a degenerate fan
    v, t, uv = _revolve(prof, pot_xy, n_theta)
    mb.add(v, t, MAT_SOIL)

    # main stem and leaves
    stem_xy = pot_xy + rng.uniform(-0.01, 0.01, 2)
    leaves, petioles = _make_leaves(rng, stem_xy)
    top = min(node[2] for node, _base in petioles) - 0.002  # the top petiole starts at the stem's tip
    v, t, uv = _tube(np.array([stem_xy[0], stem_xy[1], soil_z - 0.004]), np.array([stem_xy[0], stem_xy[1], top]), 0.004)
    mb.add(v, t, MAT_STEM, uv)
    for node, base in petioles:
        v, t, uv = _tube(node, base, 0.0022, n_around=12)
        mb.add(v, t, MAT_STEM, uv)
    for lf in leaves:
        v, t, uv = _leaf_surface(lf, MAX_EDGE)
        mb.add(v, t, MAT_LEAF0 + lf.index, uv)

    V, T, M, UV = mb.build()
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(T))
    mesh.compute_vertex_normals()
    N = np.asarray(mesh.vertex_normals).copy()
    params = {"pot_xy": pot_xy.tolist(), "pot_radii": [r_bot, r_top, r_rim, r_in], "soil_z": soil_z,
              "rim_z": z_rim_top, "stem_xy": stem_xy.tolist()}
    return Scene(V, T.astype(np.int32), M, UV, N, gz, leaves, seed, params)
