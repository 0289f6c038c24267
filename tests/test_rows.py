"""Row files read while a run merges them, and files that are not row files."""

import json

import numpy as np
import pytest

from parsim.errors import JobError
from parsim.job import parse_job
from parsim.output import rows as row_files_module
from parsim.output.dataset import row_layout
from parsim.output.rows import RowWriter, merge_rows, read_rows, row_files
from parsim.solvers import SOLVERS
from tests.datasets import small_aggregation_job

JOB = parse_job(small_aggregation_job("rows", seed=1), SOLVERS)
LAYOUT = row_layout(JOB, JOB.solver)


def statistics(value: float) -> dict:
    return {name: np.full(shape, value) for name, _, shape in LAYOUT.fields}


def write_two_ranks(folder) -> None:
    for rank, tasks in enumerate((JOB.tasks()[:5], JOB.tasks()[5:])):
        writer = RowWriter(folder, LAYOUT, JOB.name, rank)
        for task in tasks:
            writer.append(task.key, task.realization, statistics(task.point + 0.1 * task.realization))
        writer.close()


def test_a_reader_that_meets_a_merge_reads_the_merged_file(tmp_path, monkeypatch):
    write_two_ranks(tmp_path)
    expected = read_rows(tmp_path, LAYOUT)
    read_one = row_files_module._read_file
    merges = []

    def merge_in_between(path, layout):
        if not merges:  # a run starts and merges after the reader listed the files
            merges.append(path)
            merge_rows(tmp_path, LAYOUT, JOB.name)
        return read_one(path, layout)

    monkeypatch.setattr(row_files_module, "_read_file", merge_in_between)
    np.testing.assert_array_equal(read_rows(tmp_path, LAYOUT), expected)
    assert len(row_files(tmp_path)) == 1 and len(expected) == len(JOB.tasks())
    assert not merges[0].exists()  # the file listed first was gone when it was read


@pytest.mark.parametrize("change", [
    lambda header: header.pop("fields"),
    lambda header: header.update(parsim_output_schema="x"),
    lambda header: header.update(fields=[["wall_time", "float64"]]),
    lambda header: header.update(format="something else"),
])
def test_a_file_that_is_not_a_row_file_is_named(tmp_path, change):
    write_two_ranks(tmp_path)
    path = row_files(tmp_path)[0]
    lines = path.read_bytes().split(b"\n", 1)
    header = json.loads(lines[0])
    change(header)
    path.write_bytes(json.dumps(header).encode() + b"\n" + lines[1])
    with pytest.raises(JobError, match=f"^{path} is not a row file of parsim; remove it from {tmp_path}$"):
        read_rows(tmp_path, LAYOUT)
