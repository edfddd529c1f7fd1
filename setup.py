"""The simulator's compiled per-step core: every ``sim/**/*.pyx`` (Cython), built with the rest of
the package by ``pip install .`` and ``pip install -e .`` (pyproject.toml holds everything else;
``sim/compiled.py`` says which module runs).

The C code must round as the Python it replaces (the record and observation digests of
``tests/sim`` are the pure-Python path's): no contraction of a * b + c into one fused
multiply-add, no fast-math, and the C library's own sin, cos and pow (GCC would otherwise fold
sin and cos of one angle into sincos and pow(x, 2.0) into x * x)."""

from pathlib import Path

from Cython.Build import cythonize
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

setup(
    ext_modules=cythonize(
        [
            Extension(
                ".".join(source.with_suffix("").parts), [str(source)], extra_compile_args=EXACT_IEEE
            )
            for source in SOURCES
        ],
        compiler_directives={
            "language_level": 3,
            "cdivision": True,
            "boundscheck": False,
            "wraparound": False,
            "initializedcheck": False,
        },
    )
)
