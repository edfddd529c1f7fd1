"""Named per-agent-step metric terms.

A term maps one agent's driven rows to one value per row. Profiles name the terms they sum into
humanness and rules; naming a term that is not registered is an error when the profile loads.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from evaluator.scoring.profile import ScoringProfile
    from evaluator.scoring.record import AgentTrack

Term = Callable[["AgentTrack", "ScoringProfile"], np.ndarray]

_TERMS: dict[str, Term] = {}


class UnknownTermError(ValueError):
    pass


def register_term(name: str) -> Callable[[Term], Term]:
    """Decorator adding a term under ``name``; a second term with the same name is refused."""

    def add(term: Term) -> Term:
        if name in _TERMS:
            raise ValueError(f"metric term {name!r} is already registered")
        _TERMS[name] = term
        return term

    return add


def get_term(name: str) -> Term:
    try:
        return _TERMS[name]
    except KeyError:
        known = ", ".join(sorted(_TERMS))
        raise UnknownTermError(f"unknown metric term {name!r} (known: {known})") from None


def term_names() -> tuple[str, ...]:
    return tuple(sorted(_TERMS))
