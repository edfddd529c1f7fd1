"""The simulator's compiled per-step core: every ``sim/**/*.pyx`` (Cython), built with the rest of
the package by ``pip install .`` and ``pip install -e .`` (pyproject.toml holds everything else;
``sim/compiled.py`` says which module runs).

The C code must round as the Python it replaces (the record and observation digests of
``tests/sim`` are the pure-Python path's): no contraction of a * b + c into one fused
multiply-add, no fast-math, and the C library's own sin, cos and pow (GCC would otherwise fold
sin and cos of one angle into sincos and pow(x, 2.0) into x * x).

Where no compiler is found the package installs without the core (each module is an optional
extension) and the simulator runs its pure-Python reference, saying so once.
``ARENA_CORE_PREBUILT=1`` builds nothing: the modules are in place already (the Dockerfile's build
stage compiles them in an image that has a compiler, the service image copies them in)."""

import os
from pathlib import Path

from setuptools import Extension, setup

EXACT_IEEE = [
    "-O2",
    "-ffp-contract=off",
    "-fno-fast-math",
    "-fno-builtin-sin",
    "-fno-builtin-cos",
    "-fno-builtin-sincos",
    "-fno-builtin-pow",
]
SOURCES = sorted(Path("sim").rglob("*.pyx"))


def extensions() -> list[Extension]:
    if os.environ.get("ARENA_CORE_PREBUILT") == "1":
        return []
    from Cython.Build import cythonize  # a build requirement (pyproject.toml)

    modules = [
        Extension(
            ".".join(source.with_suffix("").parts), [str(source)], extra_compile_args=EXACT_IEEE
        )
        for source in SOURCES
    ]
    directives = {
        "language_level": 3,
        "cdivision": True,  # no ZeroDivisionError checks: every divisor is kept from zero
        "boundscheck": False,
        "wraparound": False,
        "initializedcheck": False,
    }
    extensions = cythonize(modules, compiler_directives=directives)
    for extension in extensions:
        extension.optional = True  # set here: cythonize does not keep it from its templates
    return extensions


setup(ext_modules=extensions())
