"""``parsim export --format mstm`` read by MSTM's own input parser and solved by MSTM (pymstm, the Python
build of Mackowski's multiple-sphere T-matrix code): the file's spheres are the task's, its size parameters
2 pi r / wavelength, and the cross sections those of MSTM given the same spheres directly."""

import math
import subprocess
import sys

import numpy as np
import pytest

from tests.readers import require

require("pymstm")

from pymstm import MSTM  # noqa: E402
from pymstm._inp_parser import parse_inp_text  # noqa: E402 - the parser of MSTM's .inp layout

import parsim  # noqa: E402
from parsim.errors import JobError  # noqa: E402
from parsim.output.export import task_spheres  # noqa: E402
from parsim.output.mstm import write_mstm  # noqa: E402
from parsim.solver import Configuration  # noqa: E402


def test_a_cluster_reads_in_mstm_as_its_spheres_in_size_parameters(tmp_path):
    cluster = parsim.aggregate(12, seed=3, dimension=3, volume_fraction=0.01)
    wavelength = 2.0 * math.pi * 0.2  # size parameter 1 for a monomer of radius 0.2
    [path] = cluster.export(tmp_path / "cluster.inp", "mstm", wavelength=wavelength,
                             refractive_index=1.6 + 0.6j)
    config = parse_inp_text(path.read_text())
    x, r = cluster.configuration.arrays["spheres/position"], cluster.configuration.arrays["spheres/radius"]
    assert config.nspheres == 12
    assert np.array_equal([[s.x, s.y, s.z] for s in config.spheres], x)  # 17 digits: the same doubles
    assert np.array_equal([s.radius for s in config.spheres], r)
    assert {(s.ref_re, s.ref_im) for s in config.spheres} == {(1.6, 0.6)}
    assert config.length_scale == 2.0 * math.pi / wavelength
    scale = config.length_scale
    from_file = MSTM(radii=[scale * s.radius for s in config.spheres],
                     positions=[(scale * s.x, scale * s.y, scale * s.z) for s in config.spheres],
                     ref_re=[s.ref_re for s in config.spheres], ref_im=[s.ref_im for s in config.spheres]).solve()
    direct = MSTM(radii=list(r * scale), positions=[tuple(p) for p in x * scale], ref_re=[1.6] * 12,
                  ref_im=[0.6] * 12).solve()
    assert from_file.q_ext_total == pytest.approx(direct.q_ext_total, rel=1e-12)
    assert from_file.q_abs_total > 0.0  # an absorbing index absorbs


def test_one_sphere_gives_mie_extinction():
    """x = 1, m = 1.5: Q_ext = 0.2151 (Mie; Bohren & Huffman's tables), and no absorption."""
    configuration = Configuration(arrays={"spheres/position": np.zeros((1, 3)), "spheres/radius": np.array([0.5]),
                                          "spheres/cluster": np.zeros(1, dtype=np.int64)},
                                  box_lower=np.full(3, -1.0), box_upper=np.full(3, 1.0), periodic=np.zeros(3, bool))
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as folder:
        path = write_mstm(task_spheres(configuration, "one"), Path(folder) / "one.inp", math.pi, 1.5 + 0.0j)[0]
        config = parse_inp_text(path.read_text())
    s = config.spheres[0]
    result = MSTM(radii=[config.length_scale * s.radius], positions=[(0.0, 0.0, 0.0)], ref_re=[s.ref_re],
                  ref_im=[s.ref_im]).solve()
    assert result.q_ext_total == pytest.approx(0.2151, abs=1e-4)
    assert abs(result.q_abs_total) < 1e-12


def test_the_command_needs_its_two_options_and_refuses_bad_ones(tmp_path):
    job = {"name": "m", "kind": "aggregation", "seed": 1, "realizations": 1,
           "parameters": {"n_spheres": 16, "volume_fraction": 0.1}}
    parsim.run(job, output=tmp_path / "m", progress=False)

    def export(*arguments):
        return subprocess.run([sys.executable, "-m", "parsim", "export", str(tmp_path / "m"), "--format", *arguments],
                              capture_output=True, text=True)

    missing = export("mstm", "--wavelength", "1.0")
    assert missing.returncode == 2 and "format 'mstm' needs --wavelength" in missing.stderr
    bad = export("mstm", "--wavelength", "1.0", "--refractive-index", "1.5-0.1j")
    assert bad.returncode == 2 and "argument --refractive-index: '1.5-0.1j': allowed: a complex number" in bad.stderr
    stray = export("csv", "--wavelength", "1.0")
    assert stray.returncode == 2 and "--wavelength: options of format 'mstm', not 'csv'" in stray.stderr
    done = export("mstm", "--wavelength", "0.5", "--refractive-index", "1.6+0.6j")
    assert done.returncode == 0, done.stderr
    assert parse_inp_text(open(done.stdout.strip()).read()).nspheres == 16
    with pytest.raises(JobError, match="--wavelength -1.0: allowed a finite number > 0"):
        parsim.aggregate(16, seed=1, volume_fraction=0.1).export(tmp_path / "x.inp", "mstm", wavelength=-1.0,
                                                                 refractive_index=1.5 + 0j)
