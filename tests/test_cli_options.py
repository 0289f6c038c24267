"""Every value option of every command, given a value it cannot take, is one line and creates nothing.

The cases are read from the command line's own parser, so an option added later is tried too.
Each option gets the bad values of its kind, as a new user types them:

- a number (``--ranks-per-task``, ``--time-limit``, ``--voxel-size``, ``--height``): inf, NaN,
  negative, zero, huge (1e300 and 10^20), a word, nothing;
- a name looked up among what exists (``--figure``, ``--task``, ``--format``): inf, NaN, negative,
  huge, a word, nothing, a name longer than a file system takes;
- a path (job files, output folders, ``--out``, ``--phase-times``): nothing, a name longer than a
  file system takes, a path below a file.

Each must end with exit status 2 and one line ``parsim: error: ...`` that names the option (or
quotes the value given), and must leave every folder as it was.  The rest of each command line is
valid: a small deposition job and its finished output.
"""

import argparse

import pytest

from parsim.cli import _parser, main
from parsim.options import NAME_MAX
from tests.datasets import run_jobs

JOB = ('name = "sediment"\nkind = "deposition"\nseed = 2\nrealizations = 1\n'
       '[parameters]\nn_particles = 40\nshape = "sphere"\nbox_length = 4.0\n')

LONG = "x" * (NAME_MAX + 45)
NUMBER_VALUES = ["inf", "nan", "-1", "0", "1e300", "100000000000000000000", "two", ""]
NAME_VALUES = ["inf", "nan", "-1", "1e300", "two", "", LONG]
PATH_VALUES = ["", LONG, "{file}/below"]
PATH_DESTS = {"job", "output", "out", "phase_times"}
NUMBER_DESTS = {"ranks_per_task", "time_limit", "voxel_size", "height"}

#: A valid command line of each command: {job} is the job file, {done} its finished output, {new} a folder
#: that does not exist yet.
VALID = {
    "run": ["run", "{job}", "--quiet", "--output", "{new}"],
    "validate": ["validate", "{job}", "--output", "{new}"],
    "compile": ["compile", "{job}"],
    "info": ["info", "{done}"],
    "plot": ["plot", "{done}", "--figure", "packing_profile", "--out", "{new}/figure"],
    "collect": ["collect", "{done}", "--out", "{new}/partial.nc"],
    "export": ["export", "{done}", "--format", "extxyz", "--out", "{new}/"],
}
#: Options whose bad values need another option to be read at all.
NEEDS = {("export", "voxel_size"): ["--format", "voxels"],
         ("export", "height"): ["--format", "voxels", "--voxel-size", "0.5"]}


def value_options():
    """(command, dest, option string or None for a positional) of every option that takes a value."""
    subparsers = next(action for action in _parser()._actions if isinstance(action, argparse._SubParsersAction))
    for command, parser in subparsers.choices.items():
        for action in parser._actions:
            if action.nargs == 0 or action.dest == "help":  # flags: nothing to give a bad value to
                continue
            yield command, action.dest, (action.option_strings[0] if action.option_strings else None)


def bad_values(dest: str) -> list[str]:
    return PATH_VALUES if dest in PATH_DESTS else NUMBER_VALUES if dest in NUMBER_DESTS else NAME_VALUES


CASES = [(command, dest, option, value) for command, dest, option in value_options() for value in bad_values(dest)]


def test_the_cases_cover_every_command():
    assert {case[0] for case in CASES} == set(VALID)
    assert len(CASES) > 100


@pytest.fixture(scope="module")
def done(tmp_path_factory):
    root = tmp_path_factory.mktemp("done")
    return run_jobs(root, {"sediment": JOB})["sediment"], root / "sediment.toml"


def command_line(command, dest, option, value, places):
    """The valid command line of ``command`` with ``value`` in place of the option ``dest``'s."""
    argv = [part.format(**places) for part in VALID[command]]
    extra = NEEDS.get((command, dest), [])
    for flag, given in [*zip(extra[::2], extra[1::2]), (option, value)]:
        if flag is None:  # the positional: the second word
            argv[1] = given
        elif flag in argv:
            argv[argv.index(flag) + 1] = given
        else:
            argv += [flag, given]
    return argv


def listing(*folders):
    return sorted(str(path) for folder in folders for path in folder.rglob("*"))


@pytest.mark.parametrize("command, dest, option, value", CASES,
                         ids=[f"{c}-{o or d}-{v[:8] or 'empty'}" for c, d, o, v in CASES])
def test_a_bad_value_is_one_line_naming_the_option_and_creates_nothing(done, tmp_path, monkeypatch, capsys,
                                                                       command, dest, option, value):
    output, job = done
    (tmp_path / "file").write_text("a file")
    value = value.format(file=tmp_path / "file")
    places = {"job": job, "done": output, "new": tmp_path / "new"}
    monkeypatch.chdir(tmp_path)  # an empty path must not mean the test's own folder
    before = listing(tmp_path, output)
    try:
        status = main(command_line(command, dest, option, value, places))
    except SystemExit as ended:  # argparse's refusal
        status = ended.code
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert status == 2 and len(lines) == 1, lines
    named = (option or dest).lstrip("-").split("-")[0]
    assert lines[0].startswith("parsim: error: ") and (named in lines[0] or (value and value[:20] in lines[0])), lines
    assert listing(tmp_path, output) == before
