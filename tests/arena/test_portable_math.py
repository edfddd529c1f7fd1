"""Values that reach records, scores, suites and observations do not depend on the CPU."""

import math
import re
from pathlib import Path

import numpy as np
import pytest

from arena import portable_math
from tests.packages import ALL

REPO = Path(__file__).resolve().parents[2]
# numpy's functions whose kernels it picks by CPU at run time (SVML's on AVX-512 machines).
CPU_DEPENDENT = re.compile(
    r"\b(?:np|numpy)\.(?:sin|cos|tan|arcsin|arccos|arctan|arctan2|sinh|cosh|tanh|arcsinh|"
    r"arccosh|arctanh|exp|exp2|expm1|log|log2|log10|log1p|power|float_power|cbrt)\s*\("
)
# Everything of the product; tests and benchmarks compare values, they make none that are kept.


@pytest.mark.parametrize(
    ("ours", "theirs"),
    [
        (portable_math.sin, math.sin),
        (portable_math.cos, math.cos),
        (portable_math.exp, math.exp),
    ],
)
def test_unary_functions_are_the_c_librarys_element_by_element(ours, theirs):
    values = np.random.default_rng(3).uniform(-7.0, 7.0, (4, 5))
    got = ours(values)
    assert got.shape == values.shape and got.dtype == np.float64
    assert got.ravel().tolist() == [theirs(v) for v in values.ravel().tolist()]
    assert ours(0.25).shape == ()  # a scalar stays one
    assert float(ours(0.25)) == theirs(0.25)


def test_arctan2_broadcasts_as_numpy_does():
    y = np.random.default_rng(4).normal(size=(3, 1))
    x = np.random.default_rng(5).normal(size=(1, 6))
    got = portable_math.arctan2(y, x)
    assert got.shape == (3, 6)
    assert got[2, 4] == math.atan2(y[2, 0], x[0, 4])
    assert portable_math.arctan2(-0.0, -1.0) == -math.pi  # signed zeros kept


def test_no_cpu_dependent_numpy_functions_in_the_product():
    found = [
        f"{path.relative_to(REPO)}:{number}: {line.strip()}"
        for package in ALL
        for path in sorted((REPO / package).rglob("*.py"))
        for number, line in enumerate(path.read_text().splitlines(), 1)
        if CPU_DEPENDENT.search(line.split("#", 1)[0])
    ]
    assert not found, "use arena.portable_math (or math) instead:\n" + "\n".join(found)
