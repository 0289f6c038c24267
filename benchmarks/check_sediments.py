"""Every sediment of a finished deposition job through the independent checker.

Reads each task file of OUTPUT/tasks and runs ``tests.sediment_checks.check_sediment`` (no
overlap, nothing outside the box or cylinder, every particle at rest, states consistent), with
the task's container, walls, floor and substrate; prints one line per task and exits with 1
if any task has a problem.

    python benchmarks/check_sediments.py output/layered_sediment [output/...]
"""

import argparse
import sys
import time
from pathlib import Path

import h5py
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests.sediment_checks from the source tree

from parsim.core.sdbd import FLOOR_ROLL, FLOOR_STOP, LATERAL_NONE, LATERAL_PERIODIC, LATERAL_WALLS  # noqa: E402
from tests.sediment_checks import check_sediment  # noqa: E402

LATERAL = {"periodic": LATERAL_PERIODIC, "walls": LATERAL_WALLS, "none": LATERAL_NONE}
FLOOR = {"stop": FLOOR_STOP, "roll": FLOOR_ROLL}


def task_problems(path: Path) -> tuple[int, list[str]]:
    """Number of particles and the checker's problems of one task file."""
    with h5py.File(path, "r") as file:
        arrays = {name: file[name][()] for name in ("spheres/position", "spheres/radius", "spheres/particle",
                                                    "particles/center_of_mass", "particles/state",
                                                    "substrate/position", "substrate/radius")}
        attrs = dict(file.attrs)
    cylinder = None
    if attrs.get("container") == "cylinder":  # centre x, y, radius, sides
        cx, cy, radius, sides = (float(value) for value in attrs["cylinder"])
        cylinder = (cx, cy, radius, int(sides))
    lateral = LATERAL_WALLS if cylinder else LATERAL[str(attrs["lateral"])]
    substrate = (arrays["substrate/position"], arrays["substrate/radius"]) if len(arrays["substrate/radius"]) else None
    problems = check_sediment(arrays["spheres/position"], arrays["spheres/radius"], arrays["spheres/particle"],
                              arrays["particles/center_of_mass"], arrays["particles/state"],
                              np.asarray(attrs["box_lower"])[:2], np.asarray(attrs["box_upper"])[:2], lateral,
                              FLOOR[str(attrs["floor"])], wall_contact=str(attrs["wall_contact"]),
                              cylinder=cylinder, substrate=substrate)
    return len(arrays["particles/state"]), problems


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("outputs", nargs="+", type=Path, help="output folders of deposition jobs")
    args = parser.parse_args()
    failed = 0
    for output in args.outputs:
        for path in sorted((output / "tasks").glob("*.h5")):
            start = time.perf_counter()
            particles, problems = task_problems(path)
            failed += bool(problems)
            verdict = "ok" if not problems else f"{len(problems)} problems: {problems[0]}"
            print(f"{output.name}/{path.stem}: {particles} particles, {verdict} ({time.perf_counter() - start:.0f} s)")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
