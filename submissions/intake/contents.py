"""What a checked, extracted submission says about itself: ``agent.yaml``, ``explanation.md``,
``requirements.txt``. Each is read with a size cap (``policy.py`` and ``train.py`` are checked by
:mod:`agent_runtime.intake`, inside the sandbox) and ``agent.yaml`` is parsed with the safe loader.
"""

from __future__ import annotations

import difflib
from enum import Enum
from pathlib import Path

import yaml
from pydantic import ValidationError

from arena.errors import IntakeError
from sim.interface import AgentInterface

POLICY = "policy.py"
TRAIN_SCRIPT = "train.py"
AGENT_YAML = "agent.yaml"
REQUIREMENTS = "requirements.txt"
EXPLANATION = "explanation.md"
# The explanation is shown on a web page; the rest of a long file is cut.
MAX_EXPLANATION_CHARS = 20_000
# A configuration file is small: a bigger one is refused before it is parsed.
MAX_CONFIG_BYTES = 64 * 1024


def read_text(
    root: Path, name: str, max_bytes: int = MAX_CONFIG_BYTES, cut: bool = False
) -> str | None:
    """A root-level text file of the submission, or None when it is absent. Longer than
    ``max_bytes``: cut there with ``cut``, else refused."""
    path = root / name
    if not path.is_file():
        return None
    with path.open("rb") as handle:
        data = handle.read(max_bytes + 1)
    if len(data) > max_bytes:
        if not cut:
            raise IntakeError(name, "file-too-large", f"is larger than {max_bytes // 1024} KiB")
        data = data[:max_bytes]
    try:
        return data.decode("utf-8-sig", errors="replace" if cut else "strict")
    except UnicodeDecodeError as error:
        raise IntakeError(name, "not-utf8", f"is not UTF-8 text ({error})") from error


def load_interface(root: Path) -> AgentInterface:
    text = read_text(root, AGENT_YAML)
    if text is None:
        return AgentInterface()
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise IntakeError(AGENT_YAML, "agent-yaml", f"is not valid YAML: {error}") from error
    except RecursionError as error:
        raise IntakeError(AGENT_YAML, "agent-yaml", "nests too deeply") from error
    if data is None:
        return AgentInterface()
    if not isinstance(data, dict):
        raise IntakeError(AGENT_YAML, "agent-yaml", "must be a mapping of option: value")
    try:
        return AgentInterface.model_validate(data)
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


def load_explanation(root: Path) -> str | None:
    text = read_text(root, EXPLANATION, MAX_EXPLANATION_CHARS * 4, cut=True)
    return None if text is None else text[:MAX_EXPLANATION_CHARS]
