"""The CF flag meanings of a swept string parameter: one word per value, each a valid CF word, no two
the same, whatever characters the values hold; a flag lookup finds each value's own code."""

import re

import netCDF4
import pytest
import xarray as xr

import parsim
from parsim.solver import flag_value, flag_words
from tests.datasets import swept_mesh_files_dataset

CF_WORD = re.compile(r"[A-Za-z0-9_.+@-]+")
"""CF 3.5: flag_meanings is a blank-separated list of words of letters, digits and _ - . + @."""

COLLIDING = [
    (["a/b.stl", "a_b.stl"], ("a_b.stl@2", "a_b.stl")),  # the value that is a word already keeps it
    (["a_b.stl", "a/b.stl"], ("a_b.stl", "a_b.stl@2")),
    (["é.csv", "ü.csv"], ("_.csv", "_.csv@2")),  # neither is a word: the first keeps it
    (["a/b", "a_b", "a_b@2"], ("a_b@3", "a_b", "a_b@2")),  # a suffixed word another value is already
    (["a/b", "a b", "a_b@2"], ("a_b", "a_b@3", "a_b@2")),
    (["sphere", "rod", ""], ("sphere", "rod", "_")),
]


@pytest.mark.parametrize("values, words", COLLIDING)
def test_values_that_cf_words_would_merge_get_distinct_words(values, words):
    assert flag_words(values) == words
    assert all(CF_WORD.fullmatch(word) for word in words)


def test_the_words_are_those_of_the_values_and_their_order_alone():
    values = ["x/1", "x_1", "x 1", "x_1@2", "x_1@3", "ü/1"]
    words = flag_words(values)
    assert len(set(words)) == len(values) and all(CF_WORD.fullmatch(word) for word in words)
    assert flag_words(list(values)) == words


def test_a_dataset_of_colliding_paths_finds_each_by_its_code(tmp_path):
    """Written and read back: each flag meaning looks up its own code, and decoded gives the paths."""
    paths = ["a/b.stl", "a_b.stl", "é.stl", "ü.stl"]
    swept_mesh_files_dataset(paths).to_netcdf(tmp_path / "meshes.nc", engine="netcdf4")
    with xr.open_dataset(tmp_path / "meshes.nc") as dataset:
        attrs = dataset.mesh_file.attrs
        meanings = attrs["flag_meanings"].split()
        assert len(set(meanings)) == len(paths)
        assert [flag_value(attrs, meaning) for meaning in meanings] == list(range(len(paths)))
        assert parsim.decoded(dataset)["mesh_file"].values.tolist() == paths
    with netCDF4.Dataset(tmp_path / "meshes.nc") as dataset:
        assert dataset["mesh_file"].flag_meanings == attrs["flag_meanings"]
