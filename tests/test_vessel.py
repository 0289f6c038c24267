"""Tests of parsim.deposition.vessel: open-topped convex vessels read from mesh files, checked, and
turned into the deposition kernel's planar faces, with exact volumes and sections."""

import math

import numpy as np
import pytest
import trimesh

from parsim.deposition.vessel import (box_mesh, hopper_mesh, prism_mesh, read_vessel, v_trough_mesh,
                                      vessel_from_mesh, wedge_mesh)
from parsim.errors import JobError
from tests.mesh_files import write

EXACT = 1e-12


def ngon_area(radius, sides):
    """Area of the regular polygon with vertices at ``radius``."""
    return 0.5 * sides * radius**2 * math.sin(2.0 * math.pi / sides)


def refusal(mesh, tmp_path, name="vessel.stl"):
    """The message of the JobError read_vessel raises on ``mesh`` written to a file."""
    with pytest.raises(JobError) as error:
        read_vessel(write(mesh, tmp_path, name))
    message = str(error.value)
    assert message.startswith("container_file: ") and "\n" not in message
    return message


def test_a_box_is_walls_and_floor_only():
    vessel = vessel_from_mesh(box_mesh(1.5, 2.0, 0.7))
    assert len(vessel.normals) == 0 and vessel.boxes.shape == (0, 6)
    assert np.allclose(vessel.upper, [1.5, 2.0, 0.7], rtol=0, atol=1e-15)
    assert vessel.volume == pytest.approx(1.5 * 2.0 * 0.7, rel=EXACT)
    for z in (0.0, 0.3, 0.7):
        assert vessel.area_at(z) == pytest.approx(3.0, rel=EXACT)
    assert vessel.volume_below(0.35) == pytest.approx(1.05, rel=EXACT)
    assert vessel.area_at(0.71) == 0.0 and vessel.area_at(-0.01) == 0.0
    normals, levels, boxes = vessel.faces()
    assert normals.dtype == levels.dtype == boxes.dtype == np.float64


def test_a_hopper_is_a_frustum():
    top, bottom, height, sides = 1.0, 0.3, 2.0, 7
    vessel = vessel_from_mesh(hopper_mesh(top, bottom, height, sides))
    a1, a2 = ngon_area(top, sides), ngon_area(bottom, sides)
    assert vessel.volume == pytest.approx(height / 3.0 * (a1 + a2 + math.sqrt(a1 * a2)), rel=EXACT)
    assert vessel.area_at(height / 2) == pytest.approx(ngon_area((top + bottom) / 2, sides), rel=EXACT)
    assert vessel.area_at(0.0) == pytest.approx(a2, rel=EXACT)
    assert vessel.volume_below(height) == pytest.approx(vessel.volume, rel=EXACT)
    assert vessel.volume_below(3 * height) == pytest.approx(vessel.volume, rel=EXACT)
    # below z, the frustum is a smaller frustum with the interpolated top
    z = 0.6
    az = ngon_area(bottom + (top - bottom) * z / height, sides)
    assert vessel.volume_below(z) == pytest.approx(z / 3.0 * (az + a2 + math.sqrt(az * a2)), rel=EXACT)
    # the bottom is the floor; every side is an inclined kernel face
    assert len(vessel.normals) == sides and np.all(vessel.normals[:, 2] > 0.0)
    assert np.allclose(np.linalg.norm(vessel.normals, axis=1), 1.0, rtol=0, atol=1e-14)
    slope = (top - bottom) * math.cos(math.pi / sides) / height  # apothem change per height
    assert np.allclose(vessel.normals[:, 2], slope / math.hypot(1.0, slope), rtol=0, atol=1e-12)
    # every vertex lies inside every face; each face's box holds its vertices
    assert np.all(vessel.vertices @ vessel.normals.T >= vessel.levels - 1e-12)
    assert np.all(vessel.boxes[:, 4] == 0.0) and np.all(vessel.boxes[:, 5] == height)


def test_inside_and_the_opening_of_a_hopper():
    top, bottom, height, sides = 1.0, 0.3, 2.0, 8
    vessel = vessel_from_mesh(hopper_mesh(top, bottom, height, sides))
    centre = vessel.upper[0] / 2  # sides % 4 == 0: the box is symmetric about the axis
    assert vessel.inside([[centre, centre, 1.0]], [0.2]).tolist() == [True]
    assert vessel.inside([[centre, centre, 0.1]], [0.2]).tolist() == [False]  # through the floor
    # a point just beyond the slanted face facing -y (side 6), at mid-height
    apothem = (top + bottom) / 2 * math.cos(math.pi / sides)
    assert vessel.inside([[centre, centre - apothem + 0.01, 1.0]], [0.0]).tolist() == [True]
    assert vessel.inside([[centre, centre - apothem - 0.01, 1.0]], [0.0]).tolist() == [False]
    # the opening is the top octagon, counter-clockwise, at the rim
    assert len(vessel.opening) == sides
    x, y = vessel.opening.T
    assert 0.5 * (np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))) == pytest.approx(ngon_area(top, sides))
    rim_apothem = top * math.cos(math.pi / sides)
    drops = np.array([[centre, centre], [centre + rim_apothem - 0.05, centre], [centre + rim_apothem + 0.01, centre]])
    assert vessel.inside_opening(drops, 0.0).tolist() == [True, True, False]
    assert vessel.inside_opening(drops, 0.1).tolist() == [True, False, False]


def test_a_hopper_with_a_rim_and_one_ending_in_an_apex():
    vessel = vessel_from_mesh(hopper_mesh(1.0, 0.3, 2.0, 8, rim=0.5))
    assert vessel.upper[2] == 2.5
    assert len(vessel.normals) == 8 + 4  # the collar's sides facing x and y are the box's walls
    collar = vessel.normals[vessel.normals[:, 2] == 0.0]
    assert len(collar) == 4 and np.all(vessel.boxes[vessel.normals[:, 2] == 0.0, 4] == 2.0)
    assert vessel.volume == pytest.approx(vessel_from_mesh(hopper_mesh(1.0, 0.3, 2.0, 8)).volume
                                          + 0.5 * ngon_area(1.0, 8), rel=EXACT)
    pyramid = vessel_from_mesh(hopper_mesh(1.0, 0.0, 2.0, 6))
    assert len(pyramid.normals) == 6 and pyramid.volume == pytest.approx(2.0 / 3.0 * ngon_area(1.0, 6), rel=EXACT)
    assert pyramid.area_at(0.0) == 0.0


def test_a_v_trough_has_two_symmetric_slopes():
    length, width, depth = 3.0, 1.0, 0.4
    vessel = vessel_from_mesh(v_trough_mesh(length, width, depth))
    assert len(vessel.normals) == 2
    first, second = vessel.normals
    assert np.allclose(first * [-1, 1, 1], second, rtol=0, atol=1e-15)  # mirror images in x = width / 2
    assert first[1] == 0.0 and first[2] == pytest.approx(width / 2 / math.hypot(width / 2, depth), rel=EXACT)
    # both planes pass through the bottom line x = width / 2, z = 0
    assert np.allclose(vessel.normals @ [width / 2, 0.0, 0.0], vessel.levels, rtol=0, atol=1e-15)
    assert vessel.volume == pytest.approx(0.5 * width * depth * length, rel=EXACT)
    assert vessel.area_at(depth / 2) == pytest.approx(width / 2 * length, rel=EXACT)
    assert vessel.area_at(0.0) == pytest.approx(0.0, abs=1e-15)


@pytest.mark.parametrize("sides", [3, 5, 6, 8, 12, 13])
def test_a_prism_has_exactly_vertical_sides(sides):
    radius, height = 1.0, 0.8
    vessel = vessel_from_mesh(prism_mesh(radius, height, sides))
    in_box = sum(1 for k in range(sides) if (4 * k) % sides == 0)  # sides facing +-x, +-y: the box's walls
    assert in_box == (4 if sides % 4 == 0 else 2 if sides % 2 == 0 else 1)
    assert len(vessel.normals) == sides - in_box
    assert np.all(vessel.normals[:, 2] == 0.0)
    assert np.allclose(np.linalg.norm(vessel.normals, axis=1), 1.0, rtol=0, atol=1e-15)
    assert vessel.volume == pytest.approx(ngon_area(radius, sides) * height, rel=EXACT)
    # the face normals point towards the axis and lie at the apothem from it
    axis = np.array([radius, radius, 0.0]) - prism_mesh(radius, height, sides).bounds[0]
    assert np.allclose(vessel.normals @ axis - vessel.levels, radius * math.cos(math.pi / sides), rtol=0, atol=1e-12)


def test_a_wedge_is_one_inclined_plane():
    vessel = vessel_from_mesh(wedge_mesh(2.0, 1.0, 2.0, 30.0, start=0.5))
    assert len(vessel.normals) == 1
    assert np.allclose(vessel.normals[0], [-0.5, 0.0, math.sqrt(3) / 2], rtol=0, atol=1e-15)
    rise = 1.5 * math.tan(math.radians(30.0))
    assert vessel.volume == pytest.approx(2.0 * 1.0 * 2.0 - 0.5 * 1.5 * rise, rel=EXACT)
    assert vessel.area_at(rise) == pytest.approx(2.0, rel=EXACT)
    assert vessel.area_at(rise / 2) == pytest.approx(1.25, rel=EXACT)


def test_read_back_from_stl_and_obj_gives_the_same_faces(tmp_path):
    mesh = hopper_mesh(1.0, 0.3, 2.0, 9, rim=0.4)
    mesh = trimesh.Trimesh(mesh.vertices.astype(np.float32).astype(np.float64), mesh.faces)  # what STL holds
    reference = vessel_from_mesh(mesh)
    for name in ("hopper.stl", "hopper.obj"):
        vessel = read_vessel(write(mesh, tmp_path, name))
        assert vessel.path.endswith(name) and len(vessel.normals) == len(reference.normals) == 9 + 9 - 1
        order, expected = np.lexsort(vessel.normals.T), np.lexsort(reference.normals.T)
        for got, want in zip(vessel.faces(), reference.faces()):
            assert np.allclose(got[order], want[expected], rtol=0, atol=1e-9)
        assert vessel.volume == pytest.approx(reference.volume, rel=1e-9)


def test_a_text_file_of_seven_significant_digits_is_read(tmp_path):
    mesh = hopper_mesh(10.0, 3.0, 20.0, 11)  # an inclined face per side, vertices rounded to 7 digits
    lines = [f"v {x:.7g} {y:.7g} {z:.7g}" for x, y, z in mesh.vertices + 100.0]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in mesh.faces]
    (tmp_path / "short.obj").write_text("\n".join(lines) + "\n")
    vessel = read_vessel(tmp_path / "short.obj")
    exact = vessel_from_mesh(mesh)
    assert len(vessel.normals) == 11 and vessel.tolerance > 1e-5
    assert np.allclose(np.sort(vessel.levels), np.sort(exact.levels), rtol=0, atol=1e-4)
    assert vessel.volume == pytest.approx(exact.volume, rel=1e-5)


def test_a_winding_turned_inside_out_changes_nothing():
    mesh = hopper_mesh(1.0, 0.3, 2.0, 6)
    turned = trimesh.Trimesh(mesh.vertices, mesh.faces[:, ::-1])
    for got, want in zip(vessel_from_mesh(turned).faces(), vessel_from_mesh(mesh).faces()):
        assert np.allclose(got, want, rtol=0, atol=1e-15)


def test_a_closed_mesh_has_no_opening(tmp_path):
    message = refusal(trimesh.creation.box(extents=(1.0, 1.0, 1.0)), tmp_path)
    assert "no opening" in message and "open top" in message


def test_a_hole_in_a_side_is_refused(tmp_path):
    mesh = box_mesh(1.0, 1.0, 1.0)
    side = np.flatnonzero(np.all(mesh.vertices[mesh.faces][:, :, 0] == 0.0, axis=1))[0]
    holed = trimesh.Trimesh(mesh.vertices, np.delete(mesh.faces, side, axis=0))
    message = refusal(holed, tmp_path)
    assert "boundary edges below its rim" in message and "closed except for its opening" in message


def test_a_bump_in_the_floor_is_not_convex(tmp_path):
    corners = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
    vertices = np.array(corners + [[x, y, 1] for x, y, _ in corners] + [[0.5, 0.5, 0.2]], dtype=float)
    floor = [[0, 1, 8], [1, 2, 8], [2, 3, 8], [3, 0, 8]]
    sides = [[k, (k + 1) % 4, 4 + (k + 1) % 4] for k in range(4)] + [[k, 4 + (k + 1) % 4, 4 + k] for k in range(4)]
    message = refusal(trimesh.Trimesh(vertices, floor + sides), tmp_path)
    assert "not convex" in message and "outside the plane of face" in message


def test_an_l_shaped_vessel_is_not_convex(tmp_path):
    outline = [(0, 0), (2, 0), (2, 1), (1, 1), (1, 2), (0, 2)]  # counter-clockwise
    vertices = np.array([(x, y, z) for z in (0.0, 1.0) for x, y in outline], dtype=float)
    floor = [[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5]]
    walls = [[k, (k + 1) % 6, 6 + (k + 1) % 6] for k in range(6)] + [[k, 6 + (k + 1) % 6, 6 + k] for k in range(6)]
    assert "not convex" in refusal(trimesh.Trimesh(vertices, floor + walls), tmp_path)


def test_a_zero_area_triangle_is_refused(tmp_path):
    mesh = box_mesh(1.0, 1.0, 1.0)
    vertices = np.vstack([mesh.vertices, [[0.5, 0.0, 0.0]]])
    a, b = [int(np.flatnonzero(np.all(mesh.vertices == p, axis=1))[0]) for p in ([0, 0, 0], [1, 0, 0])]
    faces = np.vstack([mesh.faces, [[a, len(vertices) - 1, b]]])
    message = refusal(trimesh.Trimesh(vertices, faces, process=False), tmp_path, "vessel.obj")
    assert f"1 triangles of zero area (the first is triangle {len(mesh.faces)})" in message


def test_an_overhang_is_refused(tmp_path):
    message = refusal(hopper_mesh(0.5, 1.0, 1.0, 8), tmp_path)
    assert "overhangs" in message and "points down" in message


def test_a_missing_or_unreadable_file_is_refused(tmp_path):
    with pytest.raises(JobError, match=r"^container_file: file not found: .*nothing\.stl"):
        read_vessel(tmp_path / "nothing.stl")
    (tmp_path / "garbage.stl").write_text("not a mesh\n")
    with pytest.raises(JobError, match=r"^vessel: "):
        read_vessel(tmp_path / "garbage.stl", key="vessel")


def test_two_openings_are_refused(tmp_path):
    # a box open at the top with a second, separate rim: two troughs side by side sharing no edge
    first, second = v_trough_mesh(1.0, 1.0, 0.5), v_trough_mesh(1.0, 1.0, 0.5)
    both = trimesh.util.concatenate([first, trimesh.Trimesh(second.vertices + [3.0, 0.0, 0.0], second.faces)])
    assert "2 separate loops" in refusal(both, tmp_path)
