"""Where numba caches parsim's kernels: a per-user folder, never the installed package."""

import json
import os
import subprocess
import sys
from pathlib import Path

from parsim.core.cache import CORE, _core_sources_digest

ROOT = Path(__file__).resolve().parents[1]

# Compile (or load) one cheap kernel in a fresh process and report what numba did.
PROBE = """
import json, warnings
warnings.simplefilter("always")
with warnings.catch_warnings(record=True) as caught:
    from parsim.core.cache import cache_problem
    from parsim.core.eventqueue import heap_new
    times, seqs, data = heap_new(4)
stats = heap_new.stats
print(json.dumps({
    "cache_path": stats.cache_path,
    "hits": sum(stats.cache_hits.values()),
    "misses": sum(stats.cache_misses.values()),
    "shape": list(data.shape),
    "warnings": [str(w.message) for w in caught],
    "problem": cache_problem(),
}))
"""

# Read the kernels' wall clock in a fresh process: which of parsim's kernels numba compiled, and the
# seconds a sleep took by the kernel's clock and by Python's.
CLOCK_PROBE = """
import json, time
from numba.core import event
from parsim.core.jit import defined_in_core

compiled = []
class Seen(event.Listener):
    def on_start(self, ev):
        if defined_in_core(ev.data["dispatcher"]):
            compiled.append(ev.data["dispatcher"].py_func.__qualname__)
    def on_end(self, ev):
        pass
event.register("numba:compile", Seen())
from parsim.core.sdbd.engine import _wall_clock
_wall_clock()
before, start = time.perf_counter(), _wall_clock()
time.sleep(0.2)
after, end = time.perf_counter(), _wall_clock()
print(json.dumps({"compiled": compiled, "kernel": end - start, "python": after - before}))
"""


def probe(tmp_path, code=PROBE, **env_overrides):
    env = {key: value for key, value in os.environ.items()
           if key not in ("NUMBA_CACHE_DIR", "XDG_CACHE_HOME", "NUMBA_CACHE_LOCATOR_CLASSES",
                          "NUMBA_DISABLE_JIT")}
    env["HOME"] = str(tmp_path / "home")
    env.update(env_overrides)
    # `python -c` from the repository's root, as a developer would run it
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def cache_files(folder):
    return {path: path.stat().st_mtime_ns for pattern in ("*.nbi", "*.nbc")
            for path in Path(folder).rglob(pattern)}


def test_per_user_folder_and_reuse(tmp_path):
    in_package = cache_files(CORE)
    first = probe(tmp_path, XDG_CACHE_HOME=str(tmp_path / "xdg"))
    user_dir = tmp_path / "xdg" / "parsim" / "numba"
    path = Path(first["cache_path"])
    assert path.parent.parent == user_dir  # <cpu>-<hash>/<folder>_<hash>
    assert first["misses"] == 1 and first["shape"] == [4, 5]
    files = cache_files(user_dir)
    assert {p.suffix for p in files} == {".nbi", ".nbc"} and all(p.parent == path for p in files)
    assert cache_files(CORE) == in_package  # nothing written beside the sources

    second = probe(tmp_path, XDG_CACHE_HOME=str(tmp_path / "xdg"))
    assert second["hits"] == 1 and second["misses"] == 0
    assert cache_files(user_dir) == files


def test_home_without_xdg(tmp_path):
    result = probe(tmp_path)
    user_dir = tmp_path / "home" / ".cache" / "parsim" / "numba"
    assert Path(result["cache_path"]).is_relative_to(user_dir)
    assert cache_files(tmp_path / "home")


def test_numba_cache_dir_is_honoured(tmp_path):
    result = probe(tmp_path, NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    assert Path(result["cache_path"]).parent == tmp_path / "numba"  # numba's own layout
    assert cache_files(tmp_path / "numba")
    assert not (tmp_path / "home").exists()


def test_unwritable_cache_folder_does_not_crash(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")  # a folder cannot be made below a file, even by root
    in_package = cache_files(CORE)
    result = probe(tmp_path, XDG_CACHE_HOME=str(blocker / "cache"))
    assert result["shape"] == [4, 5] and result["hits"] == 0
    assert result["warnings"] == []  # the core says nothing: the command line and the runner say it, in one line
    assert result["problem"].startswith(f"the kernel cache {blocker / 'cache' / 'parsim' / 'numba'}")
    assert result["problem"].endswith(f"cannot be written ({blocker} is a file)")
    assert cache_files(CORE) == in_package


def test_an_unwritable_numba_cache_dir_is_not_left_for_the_package_folder(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    in_package = cache_files(CORE)
    result = probe(tmp_path, NUMBA_CACHE_DIR=str(blocker / "numba"))
    assert result["hits"] == 0
    assert result["problem"] == f"the kernel cache {blocker / 'numba'} cannot be written ({blocker} is a file)"
    assert cache_files(CORE) == in_package  # numba's own fallback would have written beside the sources


def test_the_kernels_wall_clock_loads_from_the_cache(tmp_path):
    """A kernel reading the wall clock (a deposition's, for ``clock_from_particle``) is cached like any
    other: the object-mode code of a ``numba.objmode`` block is compiled again in every process, which
    made every deposition run say that it prepared the kernels.  Its clock runs as Python's."""
    first, second = (probe(tmp_path, CLOCK_PROBE, XDG_CACHE_HOME=str(tmp_path / "xdg")) for _ in range(2))
    assert "_wall_clock" in first["compiled"] and second["compiled"] == []
    assert abs(second["kernel"] - second["python"]) < 0.05, second


def test_other_numba_functions_keep_numba_defaults(tmp_path):
    (tmp_path / "user_kernel.py").write_text(
        "import numba\n\n@numba.njit(cache=True)\ndef plus_one(x):\n    return x + 1\n")
    code = ("import sys; sys.path.insert(0, sys.argv[1]); import parsim.core.jit, user_kernel; "
            "assert user_kernel.plus_one(1) == 2; print(user_kernel.plus_one.stats.cache_path)")
    env = {key: value for key, value in os.environ.items() if key != "NUMBA_CACHE_DIR"}
    env["HOME"] = str(tmp_path / "home")
    done = subprocess.run([sys.executable, "-c", code, str(tmp_path)], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert Path(done.stdout.strip()) == tmp_path / "__pycache__"


def test_stamp_covers_every_core_module(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "caller.py").write_text("x = 1\n")
    (tmp_path / "sub" / "callee.py").write_text("y = 1\n")
    before = _core_sources_digest(tmp_path)
    _core_sources_digest.cache_clear()
    (tmp_path / "sub" / "callee.py").write_text("y = 2\n")
    assert _core_sources_digest(tmp_path) != before
    _core_sources_digest.cache_clear()


# Compile parsim's kernel heap_new, a function of another package and a failing compilation, in a
# fresh process with an empty cache; report the collector's thresholds seen during and after each.
COLLECTOR_PROBE = """
import gc, json
import numba
from numba.core import event
from parsim.core.eventqueue import heap_new
from parsim.core.jit import COMPILATION_GC_THRESHOLD

during = []
class Seen(event.Listener):  # registered after parsim's listener, so it sees what that one set
    def on_start(self, ev):
        during.append(gc.get_threshold())
    def on_end(self, ev):
        pass
event.register("numba:compile", Seen())

def phase(call):
    during.clear()
    try:
        call()
    except numba.TypingError:
        pass
    return {"during": sorted(set(during)), "after": gc.get_threshold()}

gc.set_threshold(500, 5, 5)  # the process's own setting
report = {"compilation": list(COMPILATION_GC_THRESHOLD),
          "parsim": phase(lambda: heap_new(4)),
          "failed": phase(lambda: heap_new("four")),
          "other": phase(lambda: numba.njit(lambda x: x + 1)(1))}
print(json.dumps(report))
"""


def test_the_collector_runs_less_often_only_while_a_kernel_compiles(tmp_path):
    env = {key: value for key, value in os.environ.items() if key not in ("NUMBA_CACHE_DIR", "NUMBA_DISABLE_JIT")}
    env["XDG_CACHE_HOME"] = str(tmp_path / "xdg")
    done = subprocess.run([sys.executable, "-c", COLLECTOR_PROBE], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout.strip().splitlines()[-1])
    own, compiling = [500, 5, 5], report["compilation"]
    assert compiling != own
    # heap_new and the numba functions it calls compile with the raised thresholds; the process's are back after
    assert report["parsim"] == {"during": [compiling], "after": own}
    assert report["failed"] == {"during": [compiling], "after": own}  # a typing error ends the compilation too
    assert report["other"] == {"during": [own], "after": own}  # a function outside parsim/core: untouched


def test_an_index_naming_a_class_that_is_gone_is_stale(tmp_path):
    """A cache index whose signatures name a class the sources no longer have (a bundle renamed since
    the kernels were cached, e.g. by an upgrade) is stale: the kernel is compiled again, the load
    does not fail."""
    import pickle

    import parsim.core.eventqueue as module

    first = probe(tmp_path, XDG_CACHE_HOME=str(tmp_path / "xdg"))
    (index,) = Path(first["cache_path"]).glob("eventqueue.heap_new-*.nbi")
    with open(index, "rb") as file:
        version = pickle.load(file)
    renamed = type("RenamedBundle", (), {"__module__": module.__name__})
    module.RenamedBundle = renamed
    try:
        payload = pickle.dumps((_core_sources_digest(), {("signature naming it", renamed()): "old.nbc"}))
    finally:
        del module.RenamedBundle
    index.write_bytes(pickle.dumps(version) + payload)

    again = probe(tmp_path, XDG_CACHE_HOME=str(tmp_path / "xdg"))
    assert again["misses"] == 1 and again["shape"] == [4, 5]
    assert probe(tmp_path, XDG_CACHE_HOME=str(tmp_path / "xdg"))["hits"] == 1
