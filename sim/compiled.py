"""Which per-step core runs: the compiled one, or the pure-Python reference.

The hot spots of a step (lane projection and the nearest-lane search, the neighbours' states from
SUMO's report and their nearest-first order, the collision boxes, the waypoint paths, and the
arrays observation's record) have Cython versions (the ``_*.pyx`` files next to the modules they
serve, built by ``pip install .`` and ``pip install -e .`` through ``setup.py``) that do the
Python's arithmetic operation for operation, so that records and observations are the same
bytes either way (``tests/sim/test_compiled_core.py`` runs the public suite both ways). The
Python stays the reference: ``ARENA_PURE_PYTHON=1`` runs it, and it runs, with one warning,
where the compiled modules were not built. The choice is made when a module of the simulator is
first imported, so a process runs one core throughout.
"""

from __future__ import annotations

import importlib
import os
import warnings
from types import ModuleType

PURE_PYTHON_VARIABLE = "ARENA_PURE_PYTHON"
# The compiled modules; setup.py builds each from its .pyx.
MODULES = (
    "sim._boxes",
    "sim._neighbours",
    "sim._record_writer",
    "sim.road._lane_search",
    "sim.road._sampling",
)

_missing: list[str] = []


def pure_python_forced() -> bool:
    return os.environ.get(PURE_PYTHON_VARIABLE, "") not in ("", "0")


def compiled(name: str) -> ModuleType | None:
    """The compiled module ``name`` (one of :data:`MODULES`), or None where the pure-Python
    reference runs: forced by ``ARENA_PURE_PYTHON``, or the module is not built (warned once)."""
    if pure_python_forced():
        return None
    try:
        return importlib.import_module(name)
    except ImportError:
        if not _missing:
            warnings.warn(
                f"the simulator's compiled core is not built ({name} is missing): the "
                "pure-Python reference runs, several times slower per step; `pip install .` "
                "(or `pip install -e .`) with a C compiler and the Python headers builds it",
                RuntimeWarning,
                stacklevel=2,
            )
        _missing.append(name)
        return None


def core_status() -> str:
    """'compiled', 'pure-python (ARENA_PURE_PYTHON)' or 'pure-python (not built: ...)', for
    benchmarks and status lines."""
    if pure_python_forced():
        return f"pure-python ({PURE_PYTHON_VARIABLE})"
    absent = [name for name in MODULES if compiled(name) is None]
    return f"pure-python (not built: {', '.join(absent)})" if absent else "compiled"
