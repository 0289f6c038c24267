"""Benchmark: what a fresh installation pays to compile parsim's numba kernels, and a warm start.

Each measurement runs in a new process tree whose kernel cache is an empty temporary
folder (``XDG_CACHE_HOME``; ``NUMBA_CACHE_DIR`` is removed from the environment):

- ``deposition``: ``parsim.deposit(20, seed=1, box_length=5.0, packing_samples=1000)`` in
  ``python -c``, the first deposition of a user (it compiles the deposition's kernels);
- ``run``: ``parsim run`` of a job of one deposition of 20 spheres (the same point) on one
  process, into a temporary folder: the first run of a user's own deposition job;
- ``quickstart``: ``mpiexec -n 2 parsim run jobs/quickstart.toml`` into a temporary folder,
  the quick start; its line "parsim: kernels ready in X s" is reported too.

Then each runs again with the cache it has filled (the warm start).  For every run:
wall seconds, CPU seconds (user and system, of the whole process tree: both ranks and
mpiexec), the largest resident memory of one process (``wait4``) and the largest sum over
the process tree (sampled every 0.1 s: both ranks compiling at once).  The load average
before each run is printed: other processes on the machine lengthen the wall times.

    python benchmarks/compile.py [--repeat 2] [--only deposition|run|quickstart] [--ranks 2]
                                 [--no-warm] [--kernels 15] [--keep-cache]

``--kernels N`` lists the N costliest compilations of each cold run (self seconds: a
kernel's compilation minus its callees' compiled within it, from numba's "numba:compile"
events; rank 0 alone for the quick start).
"""

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
QUICKSTART = ROOT / "jobs" / "quickstart.toml"
DEPOSITION = "import parsim; parsim.deposit(20, seed=1, box_length=5.0, packing_samples=1000)"
RUN_JOB = """
name = "first"
kind = "deposition"
seed = 1
realizations = 1
[parameters]
n_particles = 20
box_length = 5.0
packing_samples = 1000
"""
WORKLOADS = ("deposition", "run", "quickstart")
PAGE = os.sysconf("SC_PAGE_SIZE")

# Run in the measured process before the workload when --kernels is given: records every
# compilation's duration from numba's events and writes the costliest (self time) to a file.
PROFILER = """
import atexit, json, os, time
from numba.core import event
_stack, _self = [], {}
class _Listener(event.Listener):
    def on_start(self, ev):
        _stack.append([time.perf_counter(), 0.0])
    def on_end(self, ev):
        start, children = _stack.pop()
        spent = time.perf_counter() - start
        if _stack:
            _stack[-1][1] += spent
        d = ev.data["dispatcher"]
        name = f"{d.py_func.__module__}.{d.py_func.__qualname__}{ev.data['args']}"
        _self[name] = _self.get(name, 0.0) + spent - children
event.register("numba:compile", _Listener())
def _write():
    rank = os.environ.get("PMI_RANK") or os.environ.get("OMPI_COMM_WORLD_RANK") or "0"  # MPICH, Open MPI
    if rank == "0":
        with open(os.environ["PARSIM_COMPILE_PROFILE"], "w") as f:
            json.dump(_self, f)
atexit.register(_write)
"""


def _children(pid):
    """Every descendant of ``pid`` (from the parent ids in /proc)."""
    parents = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
                parents.setdefault(int(fields[1]), []).append(int(entry))
            except (OSError, IndexError):
                continue
    found, todo = [], [pid]
    while todo:
        kids = parents.get(todo.pop(), [])
        found += kids
        todo += kids
    return found


def _tree_rss(pid):
    """Resident bytes of ``pid`` and its descendants, now."""
    total = 0
    for p in [pid, *_children(pid)]:
        try:
            with open(f"/proc/{p}/statm") as f:
                total += int(f.read().split()[1]) * PAGE
        except (OSError, IndexError):
            continue
    return total


def measure(command, env, cwd):
    """Run ``command``; wall and CPU seconds, peak memories, its standard error."""
    stderr_file = tempfile.TemporaryFile(mode="w+")
    start = time.perf_counter()
    process = subprocess.Popen(command, env=env, cwd=cwd, stdout=subprocess.DEVNULL, stderr=stderr_file)
    peak = [0]
    done = threading.Event()

    def sample():
        while not done.wait(0.1):
            peak[0] = max(peak[0], _tree_rss(process.pid))

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    _, status, usage = os.wait4(process.pid, 0)
    wall = time.perf_counter() - start
    done.set()
    sampler.join()
    process.returncode = os.waitstatus_to_exitcode(status)
    stderr_file.seek(0)
    stderr = stderr_file.read()
    if process.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} failed ({process.returncode}):\n{stderr}")
    return {"wall": wall, "user": usage.ru_utime, "system": usage.ru_stime,
            "max_rss": usage.ru_maxrss * 1024, "tree_rss": peak[0], "stderr": stderr}


def kernels_ready(stderr):
    """The seconds of the runner's line "parsim: kernels ready in X s", or None."""
    for line in stderr.splitlines():
        if line.startswith("parsim: kernels ready in "):
            return float(line.split()[4])
    return None


def workload(name, ranks, profile):
    """The command of a workload; with ``profile`` its processes record their compilations."""
    prefix = PROFILER if profile else ""
    if name == "deposition":
        return [sys.executable, "-c", prefix + DEPOSITION]
    run = "import sys; from parsim.cli import main; sys.exit(main(sys.argv[1:]))"
    if name == "run":
        return [sys.executable, "-c", prefix + run]
    return ["mpiexec", "-n", str(ranks), sys.executable, "-c", prefix + run]


def run_workload(name, cache, scratch, ranks, profile):
    env = {key: value for key, value in os.environ.items() if key != "NUMBA_CACHE_DIR"}
    env["XDG_CACHE_HOME"] = str(cache)
    env["PARSIM_COMPILE_PROFILE"] = str(scratch / "profile.json")
    command = workload(name, ranks, profile)
    if name in ("run", "quickstart"):
        output = scratch / "output"
        shutil.rmtree(output, ignore_errors=True)
        job = QUICKSTART
        if name == "run":
            job = scratch / "first.toml"
            job.write_text(RUN_JOB)
        command += ["run", str(job), "--output", str(output)]
    with open("/proc/loadavg") as f:
        load = float(f.read().split()[0])
    result = measure(command, env, scratch)
    result["load"] = load
    result["ready"] = kernels_ready(result["stderr"])
    if profile:
        with open(scratch / "profile.json") as f:
            result["kernels"] = json.load(f)
    return result


def describe(label, r):
    ready = f"  kernels ready {r['ready']:6.1f} s" if r["ready"] is not None else ""
    print(f"{label:24s} wall {r['wall']:6.1f} s  user {r['user']:6.1f} s  sys {r['system']:5.1f} s  "
          f"peak {r['max_rss'] / 2**30:5.2f} GiB/process {r['tree_rss'] / 2**30:5.2f} GiB/tree{ready}  "
          f"(load {r['load']:.2f})", flush=True)


def summary(label, runs):
    def median(key):
        values = [r[key] for r in runs if r[key] is not None]
        return statistics.median(values) if values else None

    ready = median("ready")
    print(f"| {label} | {median('wall'):.1f} | {median('user'):.1f} | {median('system'):.1f} | "
          f"{median('max_rss') / 2**30:.2f} | {median('tree_rss') / 2**30:.2f} | "
          f"{'' if ready is None else f'{ready:.1f}'} | {len(runs)} |")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=2, help="cold runs of each workload, each in an empty cache")
    parser.add_argument("--only", choices=WORKLOADS, action="append",
                        help="run this workload only (repeatable; default all three)")
    parser.add_argument("--ranks", type=int, default=2, help="ranks of the quick start (default 2)")
    parser.add_argument("--no-warm", action="store_true", help="skip the warm starts")
    parser.add_argument("--kernels", type=int, default=0, metavar="N",
                        help="list the N costliest compilations of each cold run")
    parser.add_argument("--keep-cache", action="store_true", help="keep the temporary folders (printed)")
    args = parser.parse_args(argv)

    names = args.only or list(WORKLOADS)
    results = {(name, kind): [] for name in names for kind in ("cold", "warm")}
    for repetition in range(args.repeat):
        for name in names:
            scratch = Path(tempfile.mkdtemp(prefix=f"parsim-compile-{name}-"))
            try:
                cache = scratch / "cache"
                cache.mkdir()
                cold = run_workload(name, cache, scratch, args.ranks, args.kernels > 0)
                results[name, "cold"].append(cold)
                describe(f"{name} cold #{repetition + 1}", cold)
                if args.kernels:
                    costly = sorted(cold["kernels"].items(), key=lambda item: -item[1])[: args.kernels]
                    total = sum(cold["kernels"].values())
                    print(f"  {len(cold['kernels'])} compilations, {total:.1f} s in all; costliest (self s):")
                    for kernel, seconds in costly:
                        print(f"  {seconds:7.2f}  {kernel}")
                if not args.no_warm:
                    warm = run_workload(name, cache, scratch, args.ranks, False)
                    results[name, "warm"].append(warm)
                    describe(f"{name} warm #{repetition + 1}", warm)
            finally:
                if args.keep_cache:
                    print(f"  kept {scratch}")
                else:
                    shutil.rmtree(scratch, ignore_errors=True)

    print("\n| run | wall s | user s | sys s | peak GiB (process) | peak GiB (tree) | kernels ready s | runs |")
    print("|---|---|---|---|---|---|---|---|")
    for (name, kind), runs in results.items():
        if runs:
            summary(f"{name} {kind}", runs)
    return 0


if __name__ == "__main__":
    sys.exit(main())
