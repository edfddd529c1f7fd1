"""What a checked, extracted submission says about itself, as the sandbox found it.

``agent.yaml``, ``requirements.txt`` and ``explanation.md`` are read and parsed by
:mod:`agent_runtime.intake` inside the sandbox, with ``policy.py`` and ``train.py``; the host
opens none of them. It receives the verdict: flat JSON, size-capped, validated here into
:class:`CheckedContents` before anything reads it, and ``agent.yaml``'s options into the
:class:`~sim.interface.AgentInterface`.
"""

from __future__ import annotations

import difflib
from enum import Enum
from typing import Annotated

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    StrictBool,
    StrictFloat,
    StrictInt,
    StrictStr,
    ValidationError,
)

from agent_runtime import intake as rules
from arena.errors import IntakeError
from sim.interface import AgentInterface

POLICY = rules.POLICY
TRAIN_SCRIPT = rules.TRAIN_SCRIPT
AGENT_YAML = rules.AGENT_YAML
REQUIREMENTS = rules.REQUIREMENTS
EXPLANATION = rules.EXPLANATION

OptionName = Annotated[StrictStr, Field(max_length=rules.MAX_OPTION_NAME)]
OptionValue = (
    StrictBool
    | StrictInt
    | StrictFloat
    | Annotated[StrictStr, Field(max_length=rules.MAX_OPTION_VALUE)]
    | None
)


class CheckedContents(BaseModel):
    """The fields of an accepted verdict the host uses (``agent_runtime.intake.read_contents``
    and ``check_scripts``), each bounded: anything else is not a verdict of ours."""

    model_config = ConfigDict(frozen=True, extra="ignore")

    trains: StrictBool
    agent_options: dict[OptionName, OptionValue] = Field(max_length=rules.MAX_OPTIONS)
    requirements: Annotated[StrictStr, Field(max_length=rules.MAX_CONFIG_BYTES)] | None
    explanation: Annotated[StrictStr, Field(max_length=rules.MAX_EXPLANATION_CHARS)] | None


def checked_contents(verdict: dict) -> CheckedContents:
    try:
        return CheckedContents.model_validate(verdict)
    except ValidationError as error:
        raise IntakeError(
            rules.ARCHIVE, "intake-crashed", f"the check's verdict is malformed ({error})"
        ) from error


def interface_of(options: dict) -> AgentInterface:
    """``agent.yaml``'s options (flat, as the sandbox parsed them) as the agent's interface."""
    try:
        return AgentInterface.model_validate(options)
    except ValidationError as error:
        problems = "; ".join(_problem(e) for e in error.errors())
        raise IntakeError(AGENT_YAML, "agent-yaml", problems) from error


def _problem(error) -> str:
    """One validation error of agent.yaml, with the nearest allowed key or value for a typo."""
    where = ".".join(str(p) for p in error["loc"]) or "agent.yaml"
    if error["type"] == "extra_forbidden":
        key = str(error["loc"][-1])
        allowed = sorted(AgentInterface.model_fields)
        return (
            f"{where}: unknown option{_did_you_mean(key, allowed)} (options: {', '.join(allowed)})"
        )
    if error["type"] == "enum" and error["loc"]:
        field = AgentInterface.model_fields.get(str(error["loc"][0]))
        if (
            field is not None
            and isinstance(field.annotation, type)
            and issubclass(field.annotation, Enum)
        ):
            allowed = [member.value for member in field.annotation]
            return f"{where}: {error['msg']}{_did_you_mean(str(error['input']), allowed)}"
    return f"{where}: {error['msg']}"


def _did_you_mean(word: str, allowed: list[str]) -> str:
    close = difflib.get_close_matches(word, allowed, n=1, cutoff=0.6)
    return f"; did you mean {close[0]!r}?" if close else ""
