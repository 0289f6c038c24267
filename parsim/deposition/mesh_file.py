"""Closed triangle meshes read from files (STL, OBJ, or another format trimesh reads).

The file is read with trimesh and checked: it must be closed (watertight: every edge joins
exactly two faces), consistently wound, and enclose a volume.  A mesh wound with inward
normals is turned.  What :func:`read_closed_mesh` returns is the kernel's
:class:`parsim.core.shapes.mesh.ClosedMesh`; :func:`particle_from_mesh_file` builds a particle
template from a file in one call.  A refused file raises ValueError naming it.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from parsim.core.shapes.mesh import ClosedMesh, equivalent_radius, mesh_particle

# A mesh enclosing less than this times the cubed diagonal has no interior.
ZERO_VOLUME_RTOL = 1e-12


@dataclass(frozen=True)
class MeshProperties:
    """The solid bounded by a mesh, in the mesh's length units: volume, surface area,
    centre of mass (uniform density), volume-equivalent radius (3 V / 4 pi)^(1/3) and
    number of faces."""

    volume: float
    area: float
    centre_of_mass: tuple
    equivalent_radius: float
    n_faces: int


def _load_mesh(path):
    """The trimesh mesh in ``path``, checked (closed, consistently wound, with volume) and
    oriented with outward normals."""
    import trimesh  # here, not at the top: only mesh particles need it

    if not Path(path).is_file():
        raise FileNotFoundError(f"mesh file not found: {path}")
    try:
        mesh = trimesh.load(path, force="mesh")
    except Exception as exc:  # trimesh's readers raise many exception types
        raise ValueError(f"{path}: cannot be read as a triangle mesh ({exc})") from exc
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ValueError(f"{path}: no triangles found")
    if not mesh.is_watertight:
        raise ValueError(f"{path}: the mesh is not closed (not watertight): "
                         "some edges do not join exactly two faces")
    if not mesh.is_winding_consistent:
        raise ValueError(f"{path}: the winding of the faces is inconsistent "
                         "(neighbouring faces point opposite ways)")
    diagonal = float(np.linalg.norm(mesh.extents))
    with np.errstate(invalid="ignore", divide="ignore"):  # trimesh's centre of mass: volume 0
        volume = float(mesh.volume)
    if abs(volume) <= ZERO_VOLUME_RTOL * diagonal**3:
        raise ValueError(f"{path}: the mesh encloses no volume")
    if volume < 0.0:  # consistently wound, but with inward normals
        mesh.invert()
    return mesh


def read_closed_mesh(path) -> ClosedMesh:
    """The checked mesh in the file ``path``, with outward normals."""
    mesh = _load_mesh(path)
    return ClosedMesh(vertices=np.asarray(mesh.vertices, dtype=np.float64),
                      faces=np.asarray(mesh.faces, dtype=np.int64),
                      volume=float(mesh.volume), diagonal=float(np.linalg.norm(mesh.extents)))


def particle_from_mesh_file(path, **options):
    """:func:`parsim.core.shapes.mesh.mesh_particle` of the mesh in ``path`` (``options``: its
    ``n_spheres``, ``tolerance``, ``samples``): ``(offsets, radii, fit)``."""
    return mesh_particle(read_closed_mesh(path), **options)


def mesh_properties(path) -> MeshProperties:
    """:class:`MeshProperties` of the solid bounded by the mesh file ``path``."""
    mesh = _load_mesh(path)
    volume = float(mesh.volume)
    return MeshProperties(
        volume=volume,
        area=float(mesh.area),
        centre_of_mass=tuple(float(x) for x in mesh.center_mass),
        equivalent_radius=equivalent_radius(volume),
        n_faces=len(mesh.faces),
    )
