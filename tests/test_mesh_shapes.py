"""Tests of parsim.core.shapes.mesh: particle templates from closed triangle meshes (STL,
OBJ) as unions of medial balls."""

import math

import numpy as np
import pytest
import trimesh

from parsim.deposition.mesh_file import mesh_properties, particle_from_mesh_file
from parsim.core.shapes.union import centre_of_mass_of_union
from tests.mesh_files import write

# Accuracy of centre_of_mass_of_union at its default resolution (documented: below 2e-4
# relative volume; margin x1.5), as in tests/test_shapes.py.
UNION_VOLUME_RTOL = 3e-4
# Protrusion allowed by the module (1e-10 of the bounding-box diagonal), with margin.
INSIDE_RTOL = 1e-9
ELLIPSOID_AXES = (3.0, 2.0, 1.0)
BOX_HALF = np.array([1.0, 0.5, 0.25])


def ellipsoid_mesh():
    """Icosphere (1280 faces) scaled to the semi-axes; vertices rounded to float32, so
    that STL (single precision) and OBJ files hold the same numbers.  The vertices lie
    on the ellipsoid (up to float32 rounding): the convex mesh is inscribed in it."""
    sphere = trimesh.creation.icosphere(subdivisions=3)
    vertices = (sphere.vertices * ELLIPSOID_AXES).astype(np.float32).astype(np.float64)
    return trimesh.Trimesh(vertices, sphere.faces, process=False)


def box_mesh():
    return trimesh.creation.box(extents=2.0 * BOX_HALF)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("meshes")
    inside_out = box_mesh()
    inside_out.invert()
    return {
        "ellipsoid.stl": write(ellipsoid_mesh(), folder, "ellipsoid.stl"),
        "ellipsoid.obj": write(ellipsoid_mesh(), folder, "ellipsoid.obj"),
        "box.stl": write(box_mesh(), folder, "box.stl"),
        "inside_out_box.stl": write(inside_out, folder, "inside_out_box.stl"),
        "sphere.stl": write(trimesh.creation.icosphere(subdivisions=3, radius=1.5), folder, "sphere.stl"),
        "torus.obj": write(trimesh.creation.torus(2.0, 0.7, major_sections=48, minor_sections=24), folder,
                           "torus.obj"),
    }


@pytest.fixture(scope="module")
def ellipsoid_series(files):
    return {n: particle_from_mesh_file(files["ellipsoid.stl"], n_spheres=n) for n in (30, 100, 300)}


def in_mesh_frame(offsets, fit):
    return offsets + np.array(fit.centre_of_mass)


def fibonacci_sphere(m):
    i = np.arange(m) + 0.5
    z = 1.0 - 2.0 * i / m
    rxy = np.sqrt(1.0 - z * z)
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    return np.stack([rxy * np.cos(phi), rxy * np.sin(phi), z], axis=1)


def distance_to_union(points, centres, radii):
    gaps = np.linalg.norm(points[:, None, :] - centres[None, :, :], axis=2) - radii[None, :]
    return np.maximum(gaps.min(axis=1), 0.0)


def exposed_sphere_points(centres, radii, per_ball):
    """Points of the balls' spheres in no other ball (the union's surface)."""
    directions = fibonacci_sphere(per_ball)
    kept = []
    for c, r in zip(centres, radii):
        points = c + r * directions
        inside = np.linalg.norm(points[:, None, :] - centres[None, :, :], axis=2) < radii * (1.0 - 1e-12)
        kept.append(points[~inside.any(axis=1)])
    return np.vstack(kept)


def test_ellipsoid_errors_small_and_not_growing_with_n_spheres(ellipsoid_series):
    previous = None
    for n, (offsets, radii, fit) in sorted(ellipsoid_series.items()):
        assert offsets.shape == (n, 3) and radii.shape == (n,) and fit.n_spheres == n
        assert offsets.dtype == radii.dtype == np.float64
        com, volume = centre_of_mass_of_union(offsets, radii)
        np.testing.assert_allclose(com, 0.0, atol=1e-9)
        assert volume == pytest.approx(fit.union_volume, rel=1e-12)
        assert fit.volume_error == pytest.approx(fit.union_volume / fit.mesh_volume - 1.0, rel=1e-12)
        assert fit.surface_distance == max(fit.mesh_to_union, fit.union_to_mesh)
        assert fit.relative_surface_distance == pytest.approx(fit.surface_distance / fit.equivalent_radius)
        # the balls are inside the mesh: the union's volume is below the mesh's
        assert fit.volume_error < UNION_VOLUME_RTOL
        if previous is not None:
            assert abs(fit.volume_error) <= abs(previous.volume_error)
            assert fit.surface_distance <= previous.surface_distance
        previous = fit
    # measured at 300 spheres: -1.75 % and 0.027 r_eq
    assert previous.volume_error > -0.025
    assert previous.relative_surface_distance < 0.04


def test_ellipsoid_union_volume_against_the_analytic_ellipsoid(ellipsoid_series):
    """union inside mesh inside ellipsoid (the convex mesh is inscribed), so
    V_union <= V_ell (up to the integration error), and
    V_union = V_mesh (1 + volume_error) >= V_ell (1 + faceting) (1 - 0.025) at 300 spheres,
    faceting = V_mesh / V_ell - 1 the mesh's own error (-0.86 % here) and 0.025 the bound
    on the volume error asserted above."""
    offsets, radii, fit = ellipsoid_series[300]
    a, b, c = ELLIPSOID_AXES
    v_ellipsoid = 4.0 / 3.0 * math.pi * a * b * c
    faceting = fit.mesh_volume / v_ellipsoid - 1.0
    assert -0.01 < faceting < 0.0
    _, v_union = centre_of_mass_of_union(offsets, radii)
    assert v_union <= v_ellipsoid * (1.0 + UNION_VOLUME_RTOL)
    assert v_union >= v_ellipsoid * (1.0 + faceting) * (1.0 - 0.025)


def test_ellipsoid_balls_are_inside_the_mesh(files, ellipsoid_series):
    mesh = trimesh.load(files["ellipsoid.stl"], force="mesh")
    diagonal = np.linalg.norm(mesh.extents)
    for offsets, radii, fit in ellipsoid_series.values():
        centres = in_mesh_frame(offsets, fit)
        # convex mesh: a ball is inside when it lies below every face plane
        heights = np.einsum("fk,bk->bf", mesh.face_normals, centres) - np.einsum(
            "fk,fk->f", mesh.face_normals, mesh.triangles[:, 0]
        )[None, :]
        assert np.max(heights + radii[:, None]) <= INSIDE_RTOL * diagonal


def test_box_balls_inside_and_surface_distance_brute_force(files):
    offsets, radii, fit = particle_from_mesh_file(files["box.stl"], n_spheres=100)
    centres = in_mesh_frame(offsets, fit)
    assert np.all(np.abs(centres) + radii[:, None] <= BOX_HALF * (1.0 + INSIDE_RTOL))
    assert -0.2 < fit.volume_error < 0.0  # measured -0.14
    assert fit.mesh_volume == pytest.approx(1.0)

    # mesh side: the corners (mesh vertices, which the module samples too) and a grid
    # on every face
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    corners = signs * BOX_HALF
    grid = np.linspace(-1.0, 1.0, 41)
    face_points = []
    for axis in range(3):
        u, v = [k for k in range(3) if k != axis]
        gu, gv = np.meshgrid(grid * BOX_HALF[u], grid * BOX_HALF[v])
        for side in (-1.0, 1.0):
            points = np.zeros((gu.size, 3))
            points[:, axis] = side * BOX_HALF[axis]
            points[:, u] = gu.ravel()
            points[:, v] = gv.ravel()
            face_points.append(points)
    corner_distance = distance_to_union(corners, centres, radii).max()
    mesh_side = max(corner_distance, distance_to_union(np.vstack(face_points), centres, radii).max())
    # union side: dense points on the spheres; the distance of an inside point to the
    # box's surface is min_k (h_k - |x_k|)
    union_points = exposed_sphere_points(centres, radii, 1000)
    union_side = np.min(BOX_HALF - np.abs(union_points), axis=1).max()

    assert fit.mesh_to_union >= corner_distance - 1e-12
    assert fit.mesh_to_union == pytest.approx(mesh_side, rel=0.05)
    # the module also samples the creases between balls, where the union's surface is
    # farthest from the mesh: it finds at least as much (up to the sampling), not less
    assert fit.union_to_mesh >= 0.97 * union_side
    assert fit.union_to_mesh <= 1.15 * union_side
    assert fit.surface_distance == pytest.approx(max(mesh_side, union_side), rel=0.15)


def test_sphere_mesh_gives_one_ball_of_the_inscribed_radius(files):
    mesh = trimesh.load(files["sphere.stl"], force="mesh")
    # radius of the largest ball in the (convex, centred) icosphere: the nearest face plane
    inscribed = np.min(np.einsum("fk,fk->f", mesh.face_normals, mesh.triangles[:, 0]))
    assert 1.49 < inscribed < 1.5
    for kwargs in ({"tolerance": 0.03}, {"n_spheres": 1}):
        offsets, radii, fit = particle_from_mesh_file(files["sphere.stl"], **kwargs)
        assert len(radii) == 1 and fit.n_spheres == 1
        np.testing.assert_allclose(offsets, 0.0, atol=1e-12)
        # the candidates touch the surface at the samples, not exactly where the largest
        # ball touches it (the faces' centres): measured 0.984 (2048 samples) and 0.993
        # (4096) times the largest radius
        assert 0.98 * inscribed <= radii[0] <= inscribed * (1.0 + INSIDE_RTOL)
        assert np.linalg.norm(fit.centre_of_mass) < 0.02 * inscribed


@pytest.mark.parametrize("name, tolerance", [("ellipsoid.stl", 0.05), ("box.stl", 0.1)])
def test_tolerance_mode_meets_its_tolerance(files, name, tolerance):
    offsets, radii, fit = particle_from_mesh_file(files[name], tolerance=tolerance)
    assert fit.relative_surface_distance <= tolerance
    assert fit.volume_error < 0.0
    # independently: every mesh vertex is within the tolerance of the union
    mesh = trimesh.load(files[name], force="mesh")
    r_eq = (3.0 * mesh.volume / (4.0 * math.pi)) ** (1.0 / 3.0)
    assert fit.equivalent_radius == pytest.approx(r_eq)
    centres = in_mesh_frame(offsets, fit)
    assert distance_to_union(mesh.vertices, centres, radii).max() <= tolerance * r_eq


def test_torus_balls_are_inside_the_non_convex_mesh(files):
    offsets, radii, fit = particle_from_mesh_file(files["torus.obj"], n_spheres=60)
    assert len(radii) == 60
    assert -0.1 < fit.volume_error < 0.0  # measured -0.05
    mesh = trimesh.load(files["torus.obj"], force="mesh")
    centres = in_mesh_frame(offsets, fit)
    triangles = mesh.triangles
    # inside: generalised winding number 1 (Jacobson et al. 2013; solid angles by Van
    # Oosterom & Strackee 1983) and distance to the surface at least the radius
    for c, r in zip(centres, radii):
        a, b, d = (triangles - c).transpose(1, 0, 2)
        la, lb, ld = (np.linalg.norm(x, axis=1) for x in (a, b, d))
        numerator = np.einsum("ij,ij->i", a, np.cross(b, d))
        denominator = la * lb * ld + np.einsum("ij,ij->i", a, b) * ld + np.einsum(
            "ij,ij->i", b, d) * la + np.einsum("ij,ij->i", d, a) * lb
        winding = np.sum(2.0 * np.arctan2(numerator, denominator)) / (4.0 * math.pi)
        assert winding == pytest.approx(1.0, abs=1e-6)
        nearest = trimesh.triangles.closest_point(triangles, np.repeat(c[None, :], len(triangles), axis=0))
        assert np.linalg.norm(nearest - c, axis=1).min() >= r - INSIDE_RTOL * np.linalg.norm(mesh.extents)


def test_stl_and_obj_of_the_same_solid_give_the_same_template(files):
    from_stl = particle_from_mesh_file(files["ellipsoid.stl"], n_spheres=40)
    from_obj = particle_from_mesh_file(files["ellipsoid.obj"], n_spheres=40)
    np.testing.assert_array_equal(from_stl[0], from_obj[0])
    np.testing.assert_array_equal(from_stl[1], from_obj[1])
    assert from_stl[2] == from_obj[2]


def test_an_inside_out_mesh_is_turned(files):
    normal = particle_from_mesh_file(files["box.stl"], n_spheres=20)
    turned = particle_from_mesh_file(files["inside_out_box.stl"], n_spheres=20)
    assert mesh_properties(files["inside_out_box.stl"]).volume == pytest.approx(1.0)
    np.testing.assert_allclose(turned[1], normal[1], rtol=1e-9)
    assert turned[2].volume_error == pytest.approx(normal[2].volume_error, rel=1e-6)


def test_mesh_properties(files):
    box = mesh_properties(files["box.stl"])
    assert box.volume == pytest.approx(1.0)
    assert box.area == pytest.approx(2.0 * (2.0 * 1.0 + 2.0 * 0.5 + 1.0 * 0.5))
    assert box.equivalent_radius == pytest.approx((3.0 / (4.0 * math.pi)) ** (1.0 / 3.0))
    np.testing.assert_allclose(box.centre_of_mass, 0.0, atol=1e-12)
    assert box.n_faces == 12


def defective_meshes():
    box = box_mesh()
    flipped = box.faces.copy()
    flipped[0] = flipped[0][::-1]
    triangle = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    return {
        "open.stl": (trimesh.Trimesh(box.vertices, box.faces[2:], process=False), "not closed"),
        "inconsistent.obj": (trimesh.Trimesh(box.vertices, flipped, process=False), "winding"),
        "flat.obj": (trimesh.Trimesh(triangle, [[0, 1, 2], [0, 2, 1]], process=False), "no volume"),  # both sides
    }


@pytest.mark.parametrize("name", sorted(defective_meshes()))
def test_defective_meshes_raise_naming_the_file(tmp_path, name):
    mesh, reason = defective_meshes()[name]
    path = write(mesh, tmp_path, name)
    for build in (lambda: particle_from_mesh_file(path, n_spheres=10), lambda: mesh_properties(path)):
        with pytest.raises(ValueError, match=reason) as info:
            build()
        assert path in str(info.value)


def test_arguments(files):
    with pytest.raises(ValueError, match="exactly one"):
        particle_from_mesh_file(files["box.stl"])
    with pytest.raises(ValueError, match="exactly one"):
        particle_from_mesh_file(files["box.stl"], n_spheres=10, tolerance=0.1)
    with pytest.raises(ValueError, match="n_spheres"):
        particle_from_mesh_file(files["box.stl"], n_spheres=0)
    with pytest.raises(ValueError, match="tolerance"):
        particle_from_mesh_file(files["box.stl"], tolerance=-1.0)
    with pytest.raises(FileNotFoundError):
        particle_from_mesh_file(files["box.stl"] + ".missing", n_spheres=10)


def test_a_mesh_particle_is_scaled_by_the_volume_of_the_mesh_not_of_its_balls(files):
    """The mesh is scaled to the volume of a sphere of radius sphere_radius; its balls, inside it,
    hold (1 + volume_error) of that volume."""
    from parsim.deposition.solver import PARAMETERS
    from parsim.deposition.materials import mesh_approximation, mesh_volume, particle_shape

    params = {p.name: p.default for p in PARAMETERS}
    params.update(shape="mesh", mesh_file=files["box.stl"], mesh_spheres=20, sphere_radius=0.7)
    _, radii, union_volume = particle_shape(params)
    fit = mesh_approximation(params)
    sphere = 4.0 / 3.0 * math.pi * 0.7**3
    assert mesh_volume(params) == pytest.approx(sphere, rel=1e-12)
    assert fit.volume_error < -0.05  # twenty balls leave much of a box's corners empty
    assert union_volume == pytest.approx(sphere * (1.0 + fit.volume_error), rel=UNION_VOLUME_RTOL)
    # the largest ball of a 2 x 1 x 0.5 box, in units of its volume-equivalent radius, times 0.7
    r_eq = (3.0 * 1.0 / (4.0 * math.pi)) ** (1.0 / 3.0)
    assert radii.max() == pytest.approx(0.7 * BOX_HALF[2] / r_eq, rel=1e-6)
