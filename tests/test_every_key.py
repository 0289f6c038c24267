"""Every key that docs/jobs.md documents refuses what no job can mean, in one line naming it,
before anything is created.

The keys come from the reference's tables (top-level keys, units, each kind's parameters,
`[[species]]` and `[[layers]]` entries), so a key added to the reference is tried without a new
test.  Each gets ``inf``, ``-inf``, a huge value, a value of the wrong type and an empty value,
in ``[parameters]`` and in ``[sweep]`` where it is swept: ``parsim validate`` must end with exit
status 2 and one line that names the key, and no output folder.  A value the reference allows
(``inf`` for a limit that it lifts, a huge limit, ``""`` for no file) must be accepted instead.
A bound the code declares must be the one the reference states.
"""

import math
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from parsim.cli import main
from parsim.solvers import SOLVERS

REFERENCE = Path(__file__).resolve().parent.parent / "docs" / "jobs.md"
HUGE_INTEGER = 2**63 - 1  # the largest TOML integer
HUGE_NUMBER = 1e300
HUGE_STRING = "x" * 100_000
BASES = {  # the parameters of a small valid job of each kind
    "aggregation": {"n_spheres": "100", "volume_fraction": "0.1"},
    "deposition": {"n_particles": "4", "box_length": "5.0"},
}
TABLE_HEADER = re.compile(r"^\| (key|`\[\[(species|layers)\]\]` key) \| type \| default \| allowed \| meaning \|$")
CELL_BORDER = re.compile(r"(?<!\\)\|")  # a | that is not written \| inside a cell
NUMBER = re.compile(r"(?<![\w.])\d+(?:\.\d+)?(?:e[+-]?\d+)?")


@dataclass(frozen=True)
class Key:
    """A key as the reference documents it: where it goes, its type and its allowed values."""

    name: str
    kind: str | None  # the solver of its table; None for a top-level key
    table: str | None  # "species" or "layers" for a key of an array of tables
    type: str
    default: str
    allowed: str

    def __str__(self) -> str:
        return f"{self.kind or 'top'}:{f'[[{self.table}]] ' if self.table else ''}{self.name}"

    @property
    def declaration(self):
        """The solver's declaration of a parameter key (None for a top-level key)."""
        if self.kind is None:
            return None
        solver = SOLVERS[self.kind]
        parameters = solver.table(self.table).parameters if self.table else solver.parameters
        return next(p for p in parameters if p.name == self.name)


def documented_keys() -> list[Key]:
    keys, kind, table, in_table = [], None, None, False
    for line in REFERENCE.read_text().splitlines():
        heading = re.match(r'^## kind = "(\w+)"', line)
        if heading:
            kind = heading.group(1)
        header = TABLE_HEADER.match(line)
        if header:
            table, in_table = header.group(2), True
            continue
        if in_table and not line.startswith("|"):
            in_table = False
        cells = [cell.strip() for cell in CELL_BORDER.split(line)[1:-1]] if in_table else []
        if cells and re.fullmatch(r"`[a-z_]+`", cells[0]):
            keys.append(Key(cells[0].strip("`"), kind, table, *cells[1:4]))
    return keys


KEYS = documented_keys()


def test_the_reference_documents_every_key_of_every_kind():
    documented = {str(key) for key in KEYS}
    for solver in SOLVERS.values():
        for parameter in solver.parameters:
            assert f"{solver.kind}:{parameter.name}" in documented
        for table in solver.tables:
            for parameter in table.parameters:
                if parameter.name not in {p.name for p in solver.parameters}:
                    assert f"{solver.kind}:[[{table.name}]] {parameter.name}" in documented
    for top in ("name", "kind", "seed", "realizations", "output", "configurations", "length_unit", "time_unit",
                "mass_unit"):
        assert f"top:{top}" in documented


def bad_values(key: Key) -> dict[str, str]:
    """The values tried, as TOML."""
    huge = {"number": repr(HUGE_NUMBER), "integer": str(HUGE_INTEGER), "string": f'"{HUGE_STRING}"',
            "true or false": repr(HUGE_NUMBER)}[key.type]
    wrong = {"number": '"0.5"', "integer": "1.5", "string": "1", "true or false": '"yes"'}[key.type]
    return {"inf": "inf", "-inf": "-inf", "huge": huge, "wrong type": wrong, "empty": '""'}


def allowed_by_the_reference(key: Key, label: str) -> bool:
    """Whether the reference allows the value ``label`` names for ``key``."""
    if label == "inf":
        return "`inf`" in key.allowed
    if label == "empty":
        return key.type == "string" and '""' in key.allowed + key.default
    if label == "huge" and key.type in ("number", "integer"):
        bounds = [float(n) for n in NUMBER.findall(key.allowed)]
        huge = HUGE_NUMBER if key.type == "number" else HUGE_INTEGER
        return "any size" in key.allowed or (bool(bounds) and huge <= max(bounds))
    return False


def job_text(key: Key, value: str, output: Path, swept: bool = False) -> str:
    """A small valid job of ``key``'s kind with ``key = value`` (in ``[sweep]`` as ``[value]`` if ``swept``)."""
    kind = key.kind or "deposition"
    top = {"name": '"k"', "kind": f'"{kind}"', "seed": "1", "realizations": "1", "output": f'"{output}"'}
    parameters, sweep, tables = dict(BASES[kind]), {}, ""
    if key.kind is None:
        top[key.name] = value
    elif key.table == "species":
        tables = f"[[species]]\nname = {value}\n" if key.name == "name" else \
            f'[[species]]\nname = "a"\n{key.name} = {value}\n'
    elif key.table == "layers":
        count = "" if key.name == "n_particles" else "n_particles = 4\n"
        tables = f'[[species]]\nname = "a"\n[[layers]]\n{count}{key.name} = {value}\n'
    elif swept:
        parameters.pop(key.name, None)
        sweep[key.name] = f"[{value}]"
    else:
        parameters[key.name] = value
    return ("".join(f"{name} = {text}\n" for name, text in top.items())
            + "[parameters]\n" + "".join(f"{name} = {text}\n" for name, text in parameters.items())
            + ("[sweep]\n" + "".join(f"{name} = {text}\n" for name, text in sweep.items()) if sweep else "")
            + tables)


def validate(text: str, folder: Path, capsys) -> tuple[int, list[str]]:
    path = folder / "job.toml"
    path.write_text(text)
    capsys.readouterr()
    status = main(["validate", str(path)])
    return status, capsys.readouterr().err.strip().splitlines()


@pytest.mark.parametrize("key", KEYS, ids=str)
def test_a_value_no_job_can_mean_is_refused_in_one_line_naming_the_key(key, tmp_path, capsys):
    output = tmp_path / "out"
    declaration = key.declaration
    places = [False] + ([True] if declaration is not None and declaration.sweepable and not key.table else [])
    for swept in places:
        for label, value in bad_values(key).items():
            status, lines = validate(job_text(key, value, output, swept), tmp_path, capsys)
            case = f"{key} = {label}{' in [sweep]' if swept else ''}"
            if allowed_by_the_reference(key, label):
                assert status in (0, 2), case
                assert status == 0 or (len(lines) == 1 and "Traceback" not in lines[0]), (case, lines)
            else:
                assert status == 2, (case, lines)
                assert len(lines) == 1 and re.search(rf"\b{key.name}\b", lines[0]), (case, lines)
            assert not output.exists(), case
    if key.kind is not None and not key.table and declaration.sweepable:
        status, lines = validate(job_text(key, "", output, swept=True), tmp_path, capsys)
        assert status == 2 and len(lines) == 1 and key.name in lines[0], lines  # an empty sweep


@pytest.mark.parametrize("key", [key for key in KEYS if key.declaration is not None
                                 and key.declaration.high not in (None, math.inf)], ids=str)
def test_the_declared_bound_is_the_one_the_reference_states(key, tmp_path, capsys):
    bound = key.declaration.high
    stated = [float(n) for n in NUMBER.findall(key.allowed)] + [math.pi] * ("π" in key.allowed)
    assert bound in stated, (key, bound, key.allowed)
    beyond = str(bound + 1) if key.type == "integer" else repr(bound * 1.5)
    status, lines = validate(job_text(key, beyond, tmp_path / "out"), tmp_path, capsys)
    assert status == 2 and len(lines) == 1 and key.name in lines[0] and "allowed" in lines[0], lines


def test_parsim_run_refuses_before_it_creates_the_folder(tmp_path):
    """The same checks stop ``parsim run`` on a terminal: one line, exit 2, no folder."""
    radius = next(key for key in KEYS if key.name == "radius")
    for text in (job_text(radius, "inf", tmp_path / "out"),
                 job_text(next(key for key in KEYS if key.name == "name"), f'"{"n" * 300}"', tmp_path / "out")):
        (tmp_path / "job.toml").write_text(text)
        result = subprocess.run([sys.executable, "-m", "parsim", "run", str(tmp_path / "job.toml")],
                                capture_output=True, text=True, timeout=120)
        assert result.returncode == 2, result.stderr
        assert len(result.stderr.strip().splitlines()) == 1, result.stderr
        assert not (tmp_path / "out").exists()
