"""Object mesh and uncertainty mesh on analytic depth maps (planes seen by a distorted camera).

Depth maps are computed exactly: for a plane n . X = c and the pixel's viewing direction
r = (x, y, 1) (undistorted, so z = 1), the depth is z = c / (n . r).
"""

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from plantreg_gui.core.camera.camera import Camera
from plantreg_gui.core.geometry.mesh import backproject_depth, boundary_edges, extend_boundary, object_mesh, uncertainty_mesh
from plantreg_gui.core.geometry.raycast import MeshScene

ROI_MIN = np.array([-0.45, -0.45, 0.30])
ROI_MAX = np.array([0.45, 0.45, 1.17])


@pytest.fixture(scope="module")
def cam():
    # like the demo's depth camera: 640x576, f ~ 504 px, noticeable distortion
    return Camera("ir", "infrared", 640, 576, [[504, 0, 321.3], [0, 504, 286.9], [0, 0, 1]],
                  [0.12, -0.05, 0.0004, -0.0003, 0.01])


@pytest.fixture(scope="module")
def rays(cam):
    return cam.rays_cam()  # exact OpenCV undistortion, (H*W, 3), z = 1


def plane_depth(rays, H, W, normal, point):
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    c = n @ np.asarray(point, float)
    with np.errstate(divide="ignore"):
        z = c / (rays @ n)
    z[~(z > 0)] = np.nan
    return z.reshape(H, W)


def tilted_normal(deg):
    """Normal of a plane inclined ``deg`` to the image plane (tilted about the x axis)."""
    a = np.radians(deg)
    return np.array([0.0, np.sin(a), -np.cos(a)])


def n_components(mesh):
    """Connected components of the mesh's vertex graph (edges of its triangles)."""
    t = mesh.triangles
    i = np.concatenate([t[:, 0], t[:, 1], t[:, 2]])
    j = np.concatenate([t[:, 1], t[:, 2], t[:, 0]])
    g = coo_matrix((np.ones(len(i)), (i, j)), shape=(mesh.n_vertices, mesh.n_vertices))
    return connected_components(g, directed=False)


def leaf_mask(cam, rays, depth, center, radius):
    P = rays * depth.reshape(-1, 1)
    return (np.linalg.norm(P - np.asarray(center), axis=1) < radius).reshape(cam.shape)


def test_backprojection_uses_intrinsics_and_distortion(cam, rays):
    H, W = cam.shape
    depth = plane_depth(rays, H, W, tilted_normal(35), [0.02, -0.01, 0.9])
    P = backproject_depth(cam, depth).reshape(-1, 3)
    ok = np.isfinite(P).all(axis=1)
    assert ok.mean() > 0.99
    # the points lie on the plane and re-project onto their own (distorted) pixel centres
    n = tilted_normal(35) / np.linalg.norm(tilted_normal(35))
    assert np.max(np.abs(P[ok] @ n - n @ [0.02, -0.01, 0.9])) < 2e-6
    uv, _ = cam.project(P[ok][::97])
    assert np.max(np.abs(uv - cam.pixel_grid()[ok][::97])) < 1e-3


def test_leaf_inclined_60_degrees_stays_one_surface(cam, rays):
    H, W = cam.shape
    center = [0.0, 0.0, 1.0]
    depth = plane_depth(rays, H, W, tilted_normal(60), center)
    leaf = leaf_mask(cam, rays, depth, center, 0.12)
    depth[~leaf] = np.nan
    for quantised in (False, True):  # also with millimetre depth steps, as a ToF camera delivers
        d = np.round(depth * 1000) / 1000 if quantised else depth
        mesh = object_mesh(cam, d, ROI_MIN, ROI_MAX, 15.0)
        ncomp, _ = n_components(mesh)
        assert ncomp == 1
        # every leaf pixel is a vertex and every quad of four leaf pixels is triangulated
        full_quads = leaf[:-1, :-1] & leaf[1:, :-1] & leaf[:-1, 1:] & leaf[1:, 1:]
        assert mesh.n_vertices == leaf.sum()
        assert mesh.n_triangles >= 2 * full_quads.sum()
        assert mesh.vertices.dtype == np.float32 and mesh.triangles.dtype == np.int32


def test_five_cm_step_between_leaves_is_cut(cam, rays):
    H, W = cam.shape
    upper = plane_depth(rays, H, W, tilted_normal(20), [0.0, 0.0, 0.95])
    lower = plane_depth(rays, H, W, tilted_normal(20), [0.0, 0.0, 1.00])
    depth = np.where(np.arange(W)[None, :] < W // 2, upper, lower)  # abutting in the image
    depth[:100] = np.nan
    mesh = object_mesh(cam, depth, ROI_MIN, ROI_MAX, 15.0)
    side = (mesh.pixel % W) < W // 2  # vertex belongs to the upper leaf
    tri_side = side[mesh.triangles]
    assert not np.any(tri_side.any(axis=1) & ~tri_side.all(axis=1)), "a triangle bridges the step"
    ncomp, _ = n_components(mesh)
    assert ncomp == 2
    # both leaves are still meshed right up to the step
    cols = mesh.pixel % W
    assert {W // 2 - 1, W // 2} <= set(np.unique(cols).tolist())


def test_edge_angle_geometry(cam, rays):
    """Cut exactly when the surface meets the line of sight below the threshold angle."""
    H, W = cam.shape
    center = [0.0, 0.0, 0.8]  # the steep planes span 0.6 .. 1.0 m over the patch, inside the ROI
    for incl, expect_kept in ((70.0, True), (80.0, False)):  # 20 and 10 degrees to the line of sight
        full = plane_depth(rays, H, W, tilted_normal(incl), center)
        depth = np.full((H, W), np.nan)
        depth[268:308, 300:340] = full[268:308, 300:340]  # 40 x 40 pixels near the optical axis
        n_quads = 39 * 39
        mesh = object_mesh(cam, depth, ROI_MIN, ROI_MAX, 15.0)
        if expect_kept:
            assert mesh.n_triangles == 2 * n_quads
        else:
            # every triangle has an edge along the slope, which is cut
            assert mesh.n_triangles == 0
        # with a 5 degree threshold even the 80 degree plane survives
        assert object_mesh(cam, depth, ROI_MIN, ROI_MAX, 5.0).n_triangles == 2 * n_quads


def test_roi_crop(cam, rays):
    H, W = cam.shape
    depth = plane_depth(rays, H, W, tilted_normal(0), [0, 0, 1.0])
    lo = np.array([-0.10, -0.2, 0.3])
    hi = np.array([0.05, 0.2, 1.17])
    mesh = object_mesh(cam, depth, lo, hi, 15.0)
    assert mesh.n_triangles > 0
    assert np.all(mesh.vertices >= lo.astype(np.float32)) and np.all(mesh.vertices <= hi.astype(np.float32))
    # the crop is the box, not less: pixels whose point lies inside are all vertices
    P = backproject_depth(cam, depth).reshape(-1, 3)
    inside = np.all((P > lo + 0.003) & (P < hi - 0.003), axis=1)
    assert set(np.flatnonzero(inside)) <= set(mesh.pixel.tolist())
    # a plane beyond the ground plane (roi max z) is not an object at all
    below = plane_depth(rays, H, W, tilted_normal(0), [0, 0, 1.19])
    assert object_mesh(cam, below, ROI_MIN, ROI_MAX, 15.0).n_triangles == 0
    # no unreferenced vertices
    assert np.array_equal(np.unique(mesh.triangles), np.arange(mesh.n_vertices))


def test_single_missing_corner_keeps_one_triangle(cam, rays):
    H, W = cam.shape
    depth = np.full((H, W), np.nan)
    depth[100:102, 200:202] = 1.0
    depth[101, 201] = np.nan
    mesh = object_mesh(cam, depth, ROI_MIN, ROI_MAX, 15.0)
    assert mesh.n_triangles == 1 and mesh.n_vertices == 3


def test_boundary_edges_of_a_rectangle(cam, rays):
    H, W = cam.shape
    depth = np.full((H, W), np.nan)
    r0, r1, c0, c1 = 200, 230, 300, 341  # 30 x 41 pixels
    depth[r0:r1, c0:c1] = plane_depth(rays, H, W, tilted_normal(30), [0, 0, 1.0])[r0:r1, c0:c1]
    mesh = object_mesh(cam, depth, ROI_MIN, ROI_MAX, 15.0)
    be = boundary_edges(mesh.triangles)
    assert len(be) == 2 * (r1 - r0 - 1) + 2 * (c1 - c0 - 1)
    rows, cols = mesh.pixel[be] // W, mesh.pixel[be] % W
    on_border = (rows == r0) | (rows == r1 - 1) | (cols == c0) | (cols == c1 - 1)
    assert on_border.all()
    # a hole in the middle adds its rim to the boundary
    depth[215, 320] = np.nan
    be2 = boundary_edges(object_mesh(cam, depth, ROI_MIN, ROI_MAX, 15.0).triangles)
    assert len(be2) == len(be) + 4


def test_uncertainty_mesh_hangs_from_boundary_to_ground(cam, rays):
    H, W = cam.shape
    center = [0.03, 0.02, 0.8]
    depth = plane_depth(rays, H, W, tilted_normal(40), center)
    depth[~leaf_mask(cam, rays, depth, center, 0.08)] = np.nan
    mesh = object_mesh(cam, depth, ROI_MIN, ROI_MAX, 15.0)
    be = boundary_edges(mesh.triangles)
    unc = uncertainty_mesh(mesh, cam.center_rig, ground_z=1.17)
    assert unc.n_triangles == 2 * len(be)
    top = unc.pixel >= 0
    floor = unc.vertices[~top]
    assert np.allclose(floor[:, 2], 1.17, atol=1e-6)
    # every floor vertex lies on the depth camera's ray through its top vertex
    t = unc.vertices[top].astype(np.float64)
    f = floor.astype(np.float64)
    cos = np.sum(t * f, axis=1) / np.linalg.norm(t, axis=1) / np.linalg.norm(f, axis=1)
    assert np.all(cos > 1 - 1e-9)
    # top vertices are exactly the boundary vertices of the object mesh
    assert np.allclose(np.sort(unc.vertices[top], axis=0), np.sort(mesh.vertices[np.unique(be)], axis=0))
    # a ray from the side through the space under the leaf meets the curtain; a ray in the open does not
    scene = MeshScene(unc.vertices, unc.triangles)
    origin = np.array([0.6, 0.0, 1.05])
    under = np.array(center) + [0, 0, 0.2]  # below the leaf, above the ground
    d = np.stack([under - origin, np.array([0.6, 0.0, 0.2]) - origin]).astype(np.float32)
    assert scene.occluded(origin, d, 1.0).tolist() == [True, False]


def test_empty_depth_gives_empty_meshes(cam):
    depth = np.full(cam.shape, np.nan)
    mesh = object_mesh(cam, depth, ROI_MIN, ROI_MAX)
    assert mesh.n_triangles == 0 and mesh.n_vertices == 0
    unc = uncertainty_mesh(mesh, cam.center_rig, 1.17)
    assert unc.n_triangles == 0
    scene = MeshScene(mesh.vertices, mesh.triangles)
    assert not scene.cast(np.zeros(3), np.array([[0, 0, 1.0]], np.float32)).hit.any()


def test_boundary_skirt_covers_the_pixel_footprints(cam, rays):
    """The mesh through pixel centres stops half a pixel short of what the boundary pixels saw;
    the skirt restores the half pixel: the extended rectangle covers exactly its pixels' footprints."""
    H, W = cam.shape
    depth = np.full((H, W), np.nan)
    r0, r1, c0, c1 = 200, 230, 300, 341
    depth[r0:r1, c0:c1] = plane_depth(rays, H, W, tilted_normal(30), [0, 0, 1.0])[r0:r1, c0:c1]
    mesh = object_mesh(cam, depth, ROI_MIN, ROI_MAX, 15.0)
    ext = extend_boundary(mesh, cam, 0.5)
    skirt = ext.pixel < 0
    assert skirt.sum() == len(np.unique(boundary_edges(mesh.triangles)))
    uv, _ = cam.project(ext.vertices[skirt])
    on_u = np.isclose(uv[:, 0], c0 - 0.5, atol=1e-3) | np.isclose(uv[:, 0], c1 - 0.5, atol=1e-3)
    on_v = np.isclose(uv[:, 1], r0 - 0.5, atol=1e-3) | np.isclose(uv[:, 1], r1 - 0.5, atol=1e-3)
    assert np.all(on_u | on_v)
    assert np.all((uv[:, 0] > c0 - 0.5 - 1e-3) & (uv[:, 0] < c1 - 0.5 + 1e-3))
    assert np.all((uv[:, 1] > r0 - 0.5 - 1e-3) & (uv[:, 1] < r1 - 0.5 + 1e-3))
    # rays of the depth camera just inside the footprint hit the extended mesh, just outside do not
    probe = np.array([[c0 - 0.4, 215.2], [c0 - 0.6, 215.2], [320.3, r1 - 0.6], [320.3, r1 - 0.4]])
    o, d = cam.rays_rig(probe)
    assert MeshScene(ext.vertices, ext.triangles).cast(o, d.astype(np.float32)).hit.tolist() == [True, False, True, False]
    assert not MeshScene(mesh.vertices, mesh.triangles).cast(o, d.astype(np.float32)).hit[0]
    # the uncertainty mesh now hangs from the skirt
    unc = uncertainty_mesh(ext, cam.center_rig, 1.17)
    assert unc.n_triangles == 2 * len(boundary_edges(ext.triangles)) == 2 * len(boundary_edges(mesh.triangles))


def test_no_skirt_at_noise_holes(cam, rays):
    """A small depth jump (noise cutting a hole into one surface) gets no skirt; a leaf edge does."""
    H, W = cam.shape
    depth = np.full((H, W), np.nan)
    depth[200:230, 300:341] = plane_depth(rays, H, W, tilted_normal(0), [0, 0, 1.0])[200:230, 300:341]
    depth[215, 320] += 0.009  # cuts its edges (9 mm over 2 mm) but is no surface edge
    mesh = object_mesh(cam, depth, ROI_MIN, ROI_MAX, 15.0)
    ext = extend_boundary(mesh, cam, 0.5, depth)
    uv, _ = cam.project(ext.vertices[ext.pixel < 0])
    inner = (np.abs(uv[:, 0] - 320) < 3) & (np.abs(uv[:, 1] - 215) < 3)
    assert not inner.any()  # nothing around the hole
    assert len(uv) == 2 * (29 + 40)  # the whole outer rim
    assert np.array_equal(np.unique(ext.triangles), np.arange(ext.n_vertices))


def test_transport_pixels_uses_the_requested_boundary_skirt(cam, rays):
    """The same depth map meshed with and without the skirt: a pixel half-way into the boundary
    pixel's outer half is carried only with the skirt (the mesh cache must not mix them up)."""
    from plantreg_gui.core.registration.params import RegistrationParams
    from plantreg_gui.core.registration.transport import transport_pixels
    from plantreg_gui.core.camera.rig import Rig

    H, W = cam.shape
    depth = np.full((H, W), np.nan, dtype=np.float32)
    r0, r1, c0, c1 = 200, 230, 300, 341
    depth[r0:r1, c0:c1] = plane_depth(rays, H, W, tilted_normal(30), [0, 0, 1.0])[r0:r1, c0:c1]
    rig = Rig([cam], depth_camera="ir", roi_min=ROI_MIN, roi_max=ROI_MAX)
    probe = np.array([[c0 - 0.4, 215.2], [320.3, 215.2]])
    with_skirt = transport_pixels(rig, depth, "ir", probe, "ir", RegistrationParams(boundary_px=0.5))
    without = transport_pixels(rig, depth, "ir", probe, "ir", RegistrationParams(boundary_px=0.0))
    assert np.allclose(with_skirt, probe, atol=1e-3)          # both carried, back onto themselves
    assert np.isnan(without[0]).all() and np.allclose(without[1], probe[1], atol=1e-3)
