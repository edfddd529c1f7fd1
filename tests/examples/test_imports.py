"""The example agents are data folders, not packages of ours: what runs in the sandbox imports
nothing of this project, and a training script run on the participant's machine imports only the
kit's public modules, the table of docs/training.md ("What your code may import from the kit")."""

from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path

import pytest

from arena.examples import examples_dir
from tests.packages import ALL

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = examples_dir()
OURS = set(ALL)


def documented_public_modules() -> set[str]:
    text = (ROOT / "docs" / "training.md").read_text()
    section = text.split("## What your code may import from the kit", 1)[1].split("\n## ", 1)[0]
    return set(re.findall(r"^\| `([\w.]+)` \|", section, flags=re.M))


def imported_modules(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module)
    return names


def ours(module: str) -> bool:
    return module.split(".")[0] in OURS


FILES = sorted(EXAMPLES.glob("*/*.py"))


def test_the_table_is_found_and_names_the_environments():
    assert {"learn.gym_env", "learn.parallel_env"} <= documented_public_modules()


def test_example_folders_are_not_packages():
    assert not list(EXAMPLES.glob("**/__init__.py"))


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(EXAMPLES)))
def test_examples_import_only_the_documented_public_modules(path):
    imported = {m for m in imported_modules(path) if ours(m)}
    # The sandbox holds no package of ours: only a training script run locally may use the kit.
    allowed = documented_public_modules() if path.name == "train.py" else set()
    assert imported <= allowed, f"{path.name} imports {sorted(imported - allowed)}"
    for module in imported:
        importlib.import_module(module)  # a documented module that exists
