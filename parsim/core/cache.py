"""Where numba keeps the compiled machine code of parsim's kernels.

Numba's ``cache=True`` writes ``*.nbi`` (index) and ``*.nbc`` (machine code) files beside the
source by default, in ``__pycache__`` folders of the installed package. pip does not know
these files: uninstalling parsim (e.g. ``pip install -e .`` after ``pip install .``) leaves
``site-packages/parsim/core/__pycache__`` behind, and Python then imports that left-over
folder as an empty namespace package ``parsim.core`` in place of the real one. parsim's
kernels are therefore cached per user, outside the package::

    $XDG_CACHE_HOME/parsim/numba/<cpu>-<hash>/<folder>_<hash>/   (default ~/.cache/parsim/numba/...)

- ``<cpu>-<hash>``: the machine code's target. ``<cpu>`` is the CPU model LLVM compiles for
  (``llvmlite.binding.get_host_cpu_name()``, or ``NUMBA_CPU_NAME``); the hash covers the
  target triple, the CPU features (``NUMBA_CPU_FEATURES``, ``NUMBA_ENABLE_AVX``) and the
  numba version. Nodes with different CPUs or numba versions that share one home directory
  thus keep separate index files instead of overwriting each other's.
- ``<folder>_<hash>``: numba's own naming, one folder per source folder (its name and a
  hash of its path), so that several installations (virtual environments, clones) do not
  mix.
- Index files are stamped with a hash of every source file of :mod:`parsim.core`, not
  just the kernel's own file: numba compiles callees from other modules into the
  caller's machine code but checks only the caller's file, so an edit in a callee module
  would otherwise go unnoticed. Any edit in ``parsim/core`` recompiles the kernels.
- An index that cannot be read, such as one whose signatures name a bundle renamed since it
  was written (numba unpickles an index before it compares stamps), is stale too.

Only functions defined in ``parsim/core`` are concerned (a locator registered in front of
numba's own); other numba functions in the same process keep numba's defaults.
``NUMBA_CACHE_DIR``, when set, takes precedence: the files go where numba puts them
(``$NUMBA_CACHE_DIR/<folder>_<hash>/``, no per-CPU folder).
If the folder cannot be created or written, the kernels are compiled without caching, in every
process (not in numba's fallback, the package's ``__pycache__``); :func:`cache_problem` says why,
for the command line and the runner to say (the core prints nothing). Deleting the cache folder
is always safe.
"""

import functools
import hashlib
import os
import pickle
import re
import tempfile
from pathlib import Path

import numba
from numba.core import caching, config

__all__ = ["kernel_cache_dir", "cache_problem", "cache_usable", "install", "CACHE_REMEDY"]

#: The folder of parsim's kernels: functions defined in files below it use the locator.
CORE = Path(__file__).resolve().parent
#: What to do when the kernels cannot be cached.
CACHE_REMEDY = "set XDG_CACHE_HOME (or NUMBA_CACHE_DIR) to a writable folder"


def _user_cache_home():
    """``$XDG_CACHE_HOME`` if it is an absolute path, else ``~/.cache``."""
    xdg = os.environ.get("XDG_CACHE_HOME", "")
    if os.path.isabs(xdg):
        return Path(xdg)
    return Path.home() / ".cache"


@functools.cache
def _machine_tag():
    """``<cpu>-<hash>``: what the compiled code depends on, as numba's codegen sees it."""
    import llvmlite.binding as ll
    from numba.core.codegen import get_host_cpu_features

    cpu = config.CPU_NAME or ll.get_host_cpu_name()
    features = config.CPU_FEATURES if config.CPU_FEATURES is not None else get_host_cpu_features()
    key = repr((ll.get_process_triple(), cpu, features, numba.__version__))
    digest = hashlib.sha256(key.encode()).hexdigest()[:12]
    return f"{re.sub(r'[^A-Za-z0-9._-]', '_', cpu) or 'cpu'}-{digest}"


def kernel_cache_dir():
    """The folder under which parsim's kernels are cached, as described above."""
    if config.CACHE_DIR:
        return Path(config.CACHE_DIR)
    return _user_cache_home() / "parsim" / "numba" / _machine_tag()


@functools.cache
def cache_problem():
    """Why the kernels cannot be cached, as "the kernel cache FOLDER cannot be written (REASON)", or None
    when they can; found once per process, by making the folder and a file in it.
    """
    try:
        path = kernel_cache_dir()
    except RuntimeError as error:  # Path.home() without a home
        return f"the kernel cache has no folder ({error})"
    try:
        path.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=path).close()
    except OSError as error:
        return f"the kernel cache {path} cannot be written ({_obstacle(path, error)})"
    return None


def _obstacle(path, error):
    """What kept ``path`` from being made or written: a file where a folder should be, else the system's reason
    (and the folder it names)."""
    existing = next(folder for folder in (path, *path.parents) if os.path.exists(folder))
    if not existing.is_dir():
        return f"{existing} is a file"
    return f"{error.strerror}: {error.filename}" if error.strerror and error.filename else str(error)


def cache_usable():
    """Whether the kernels can be cached (:func:`cache_problem` found nothing against it)."""
    return cache_problem() is None


@functools.cache
def _core_sources_digest(root=CORE):
    """A hash of every ``*.py`` file below ``root`` (names and contents), once per process."""
    digest = hashlib.sha256()
    for path in sorted(Path(root).rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0")
        digest.update(path.read_bytes() + b"\0")
    return digest.hexdigest()


def _in_core(py_file):
    try:
        return Path(py_file).resolve().is_relative_to(CORE)
    except (OSError, ValueError):
        return False


class ParsimCacheLocator(caching._CacheLocator):
    """Numba cache locator for the functions defined in ``parsim/core``; see the module."""

    def __init__(self, py_func, py_file):
        self._py_file = py_file
        self._lineno = py_func.__code__.co_firstlineno
        subpath = self.get_suitable_cache_subpath(py_file)
        self._cache_path = str(kernel_cache_dir() / subpath)

    def get_cache_path(self):
        return self._cache_path

    def get_source_stamp(self):
        return _core_sources_digest()

    def get_disambiguator(self):
        return str(self._lineno)

    @classmethod
    def from_function(cls, py_func, py_file):
        if not (os.path.isfile(py_file) and _in_core(py_file)):
            return None
        try:
            self = cls(py_func, py_file)
            self.ensure_cache_path()
        except (OSError, RuntimeError):
            return None  # numba tries its own locators next
        return self


#: What unpickling an index raises when its signatures name a class or module the sources no longer
#: have (a bundle renamed since the kernels were cached), or when the file is cut short
_UNREADABLE_INDEX = (AttributeError, ImportError, EOFError, pickle.UnpicklingError)


def _stale_if_unreadable(load_index):
    """numba's index loader, for which an index of parsim's kernels that cannot be unpickled is stale
    (an empty index: the kernel is compiled again and the index rewritten), as one of other sources
    is.  numba unpickles an index before it compares its source stamp, so an index written by other
    sources can name what these sources lack."""

    @functools.wraps(load_index)
    def load(self):
        try:
            return load_index(self)
        except _UNREADABLE_INDEX:
            if Path(self._index_path).resolve().is_relative_to(kernel_cache_dir().resolve()):
                return {}
            raise

    load.parsim_tolerant = True
    return load


def install():
    """Put :class:`ParsimCacheLocator` in front of numba's locators (once), and make an unreadable
    index of parsim's kernels stale (:func:`_stale_if_unreadable`)."""
    impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl
    locators = impl._locator_classes
    if not any(cls.__name__ == ParsimCacheLocator.__name__ for cls in locators):
        locators.insert(0, ParsimCacheLocator)
    index_file = caching.IndexDataCacheFile
    if not getattr(index_file._load_index, "parsim_tolerant", False):
        index_file._load_index = _stale_if_unreadable(index_file._load_index)
