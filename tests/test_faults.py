"""Malformed inputs through the real command line.

Each case is one bad input, given to ``parsim validate`` and, for most, to ``parsim run``:
the command must exit with status 2 after printing exactly one line on standard error,
``parsim: error: ...`` naming the offending key or file, without a traceback or a warning,
and must not create the job's output folder.
"""

import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

REPOSITORY = Path(__file__).resolve().parent.parent

AGGREGATION = """\
name = "faults"
kind = "aggregation"
seed = 1
realizations = 1
output = "{out}"
[parameters]
n_spheres = 16
volume_fraction = 0.1
"""

DEPOSITION = """\
name = "faults"
kind = "deposition"
seed = 1
realizations = 1
output = "{out}"
[parameters]
n_particles = 10
box_length = 20.0
packing_samples = 1000
"""

AGGLOMERATE = DEPOSITION + 'shape = "agglomerate"\nagglomerate_file = "{folder}/flake{suffix}"\n'
MESH = DEPOSITION + 'shape = "mesh"\nmesh_file = "{folder}/flake{suffix}"\nmesh_spheres = 20\n'


def cube_obj(half: float) -> bytes:
    """An OBJ file of the closed cube [-half, half]^3, its faces wound outwards (corner 4x + 2y + z)."""
    corners = [(x, y, z) for x in (-half, half) for y in (-half, half) for z in (-half, half)]
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in corners]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for q in quads for a, b, c in ((q[0], q[1], q[2]), (q[0], q[2], q[3]))]
    return ("\n".join(lines) + "\n").encode()


@dataclass
class Fault:
    """A job file and what the error line must name.

    ``{out}``, ``{folder}`` and ``{suffix}`` in ``job`` become the output folder, the test's
    folder and the agglomerate file's suffix; an empty ``job`` stands for a missing job file.
    """

    job: str
    names: str
    flake: bytes | None = None  #: content of the input file ``{folder}/flake{suffix}`` (agglomerate or mesh)
    suffix: str = ".csv"
    encoding: str = "utf-8"  #: of the job file


def changed(base: str, old: str, new: str) -> str:
    assert old in base
    return base.replace(old, new, 1)


FAULTS = {
    "unknown top-level key": Fault(changed(AGGREGATION, "seed = 1", "seed = 1\ncolour = 1"), "'colour'"),
    "missing top-level key": Fault(changed(AGGREGATION, "seed = 1\n", ""), "'seed'"),
    "unknown parameter": Fault(AGGREGATION + "radiuss = 0.2\n", "'radiuss'"),
    "string for a number": Fault(AGGREGATION + 'radius = "big"\n', "radius = 'big'"),
    "float for an integer": Fault(changed(AGGREGATION, "n_spheres = 16", "n_spheres = 16.0"), "n_spheres = 16.0"),
    "float for an integer (deposition)": Fault(changed(DEPOSITION, "n_particles = 10", "n_particles = 10.0"),
                                               "n_particles = 10.0"),
    "float for realizations": Fault(changed(AGGREGATION, "realizations = 1", "realizations = 1.0"), "realizations"),
    "bool for a number": Fault(changed(AGGREGATION, "volume_fraction = 0.1", "volume_fraction = true"),
                               "volume_fraction = True"),
    "integer beyond 64 bits": Fault(AGGREGATION + "radius = 100000000000000000000\n", "radius"),
    "negative radius": Fault(AGGREGATION + "radius = -1\n", "radius = -1.0"),
    "negative seed": Fault(changed(AGGREGATION, "seed = 1", "seed = -1"), "seed = -1"),
    "volume fraction beyond 1": Fault(changed(AGGREGATION, "volume_fraction = 0.1", "volume_fraction = 1.5"),
                                      "volume_fraction"),
    "lattice does not fit": Fault(changed(AGGREGATION, "volume_fraction = 0.1", "volume_fraction = 0.9"),
                                  "volume_fraction"),
    "box smaller than a particle": Fault(changed(DEPOSITION, "box_length = 20.0", "box_length = 1.0"), "box_length"),
    "empty sweep": Fault(AGGREGATION + "[sweep]\nradius = []\n", "radius"),
    "duplicate sweep values": Fault(AGGREGATION + "[sweep]\nradius = [0.2, 0.2]\n", "radius"),
    "sweep of a single value": Fault(AGGREGATION + "[sweep]\nradius = 0.2\n", "radius"),
    "unsweepable key": Fault(AGGREGATION + "[sweep]\ndimension = [2, 3]\n", "'dimension'"),
    "too many tasks": Fault(changed(AGGREGATION, "realizations = 1", "realizations = 1000000000000"),
                            "realizations"),
    "unknown kind": Fault(changed(AGGREGATION, '"aggregation"', '"aggregate"'), "kind = 'aggregate'"),
    "unknown method": Fault(AGGREGATION + 'method = "magic"\n', "method = 'magic'"),
    "unknown shape": Fault(DEPOSITION + 'shape = "blob"\n', "shape = 'blob'"),
    "missing job file": Fault("", "nowhere.toml"),
    "job file that is binary": Fault("\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", "job.toml", encoding="latin-1"),
    "job file that is not UTF-8": Fault(changed(AGGREGATION, '"faults"', '"caf\xe9"'), "job.toml", encoding="latin-1"),
    "job file with NUL bytes": Fault("\x00\x00\x00\x01", "job.toml"),
    "invalid TOML": Fault(changed(AGGREGATION, '"faults"', '"faults'), "job.toml"),
    "integer of 5000 digits": Fault(AGGREGATION + "radius = 1" + "0" * 5000 + "\n", "job.toml"),
    "missing agglomerate file": Fault(AGGLOMERATE, "agglomerate_file", suffix=".h5"),
    "agglomerate .h5 that is not HDF5": Fault(AGGLOMERATE, "agglomerate_file", b"x,y,z,r\n0,0,0,1\n", ".h5"),
    "agglomerate CSV with a word": Fault(AGGLOMERATE, "agglomerate_file", b"x,y,z,r\n0,0,0,1\n0,one,0,1\n"),
    "agglomerate CSV that is empty": Fault(AGGLOMERATE, "agglomerate_file", b""),
    "agglomerate CSV with ragged rows": Fault(AGGLOMERATE, "agglomerate_file", b"x,y,z,r\n0,0,0,1\n0,0,1\n"),
    "agglomerate CSV that is binary": Fault(AGGLOMERATE, "agglomerate_file", b"\x89PNG\r\n\x1a\n\x00"),
    "mesh of coordinates near 1e200": Fault(MESH, "mesh_file", cube_obj(1e200), ".obj"),
    "aggregation beyond memory": Fault(changed(AGGREGATION, "n_spheres = 16", "n_spheres = 1000000000000"),
                                       "n_spheres=1000000000000"),
    "deposition beyond memory": Fault(changed(DEPOSITION, "n_particles = 10", "n_particles = 1000000000000"),
                                      "n_particles=1000000000000"),
}

VALIDATE_ONLY = (
    "missing top-level key", "unknown parameter", "string for a number", "float for an integer (deposition)",
    "float for realizations", "bool for a number", "integer beyond 64 bits", "negative seed",
    "volume fraction beyond 1", "duplicate sweep values", "sweep of a single value", "unknown method",
    "job file that is binary", "job file with NUL bytes", "integer of 5000 digits",
    "agglomerate CSV with ragged rows", "agglomerate CSV that is binary",
)
"""Variants of a family that ``run`` meets too: ``validate`` alone keeps the battery short."""

CASES = [pytest.param(fault, command, id=f"{command}: {name}") for name, fault in FAULTS.items()
         for command in (("validate",) if name in VALIDATE_ONLY else ("validate", "run"))]


def written(fault: Fault, folder: Path) -> Path:
    """Write the job file and agglomerate file of ``fault`` in ``folder``; the job file's path."""
    if fault.flake is not None:
        (folder / f"flake{fault.suffix}").write_bytes(fault.flake)
    if not fault.job:
        return folder / "nowhere.toml"
    job = folder / "job.toml"
    job.write_bytes(fault.job.format(out=folder / "out", folder=folder, suffix=fault.suffix).encode(fault.encoding))
    return job


@pytest.mark.parametrize("fault, command", CASES)
def test_a_bad_input_gets_one_line_and_creates_nothing(fault, command, tmp_path):
    job = written(fault, tmp_path)
    result = subprocess.run([sys.executable, "-m", "parsim.cli", command, str(job)], capture_output=True, text=True,
                            cwd=REPOSITORY, timeout=120)

    lines = result.stderr.splitlines()
    assert result.returncode == 2, result.stderr
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("parsim: error: ") and fault.names in lines[0], lines[0]
    assert "Traceback" not in result.stderr and "Warning" not in result.stderr
    assert not (tmp_path / "out").exists()


def test_a_mesh_trimesh_cannot_compute_with_says_why_in_its_line(tmp_path):
    """The cube that is refused at 1e200 is a valid mesh at 1: the line names the arithmetic, not the shape."""
    for half, status in ((1.0, 0), (1e200, 2)):
        job = written(Fault(MESH, "mesh_file", cube_obj(half), ".obj"), tmp_path)
        result = subprocess.run([sys.executable, "-m", "parsim.cli", "validate", str(job)], capture_output=True,
                                text=True, cwd=REPOSITORY, timeout=300)
        assert result.returncode == status, result.stderr
        if status:
            (line,) = result.stderr.splitlines()
            assert "trimesh could not compute with its coordinates (invalid value encountered in cast)" in line
            assert line.endswith("give finite coordinates below 1e10 in size (the particle is scaled to sphere_radius "
                                 "whatever the mesh's size)")
        else:
            assert result.stderr == "", result.stderr
