"""What a benchmark needs, checked before it starts: every missing piece named at once, with how
to install it, instead of a failure minutes in. Not a benchmark itself (no smoke mode)."""

from __future__ import annotations

import importlib.util
import shutil
import sys


def tool(name: str, how: str) -> str | None:
    """Why the program ``name`` is missing (``how``: what installs it), or None."""
    return None if shutil.which(name) else f"{name}: {how}"


def module(name: str, how: str) -> str | None:
    """Why the Python module ``name`` is missing, or None."""
    return None if importlib.util.find_spec(name) else f"Python module {name}: {how}"


def require(*problems: str | None) -> None:
    """Exit with status 2 naming every problem (None: fine)."""
    found = [problem for problem in problems if problem]
    if found:
        sys.exit("missing prerequisites:\n  " + "\n  ".join(found))
