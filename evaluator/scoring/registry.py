"""Named per-agent-step metric terms: the registry imports every term module and names its
terms (:data:`TERMS` of each), refusing a name given twice.

A term (:mod:`evaluator.scoring.term`) maps one agent's driven rows to one value per row.
Profiles name the terms they sum into humanness and rules; naming a term that is not registered
is an error when the profile loads.
"""

from __future__ import annotations

from collections.abc import Callable

from arena.errors import ArenaError
from evaluator.scoring import reference_terms, terms
from evaluator.scoring.term import Term

_TERMS: dict[str, Term] = {}


class UnknownTermError(ArenaError, ValueError):
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


for _module in (terms, reference_terms):
    for _name, _term in _module.TERMS.items():
        register_term(_name)(_term)
