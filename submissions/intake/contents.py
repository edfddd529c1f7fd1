"""Checks of what a submission holds: ``policy.py``, ``agent.yaml``, ``explanation.md``.

Nothing of the participant's is imported or run on the host: ``policy.py`` is compiled and its
syntax tree searched for a ``Policy`` definition, and ``agent.yaml`` is parsed with the safe loader.
"""

from __future__ import annotations

import ast
import difflib
import zipfile
from enum import Enum

import yaml
from pydantic import ValidationError

from arena.errors import IntakeError
from sim.interface import AgentInterface
from submissions.intake.archive import read_entry

POLICY = "policy.py"
TRAIN_SCRIPT = "train.py"
AGENT_YAML = "agent.yaml"
REQUIREMENTS = "requirements.txt"
EXPLANATION = "explanation.md"
# The explanation is shown on a web page; the rest of a long file is cut.
MAX_EXPLANATION_CHARS = 20_000


def read_text(archive: zipfile.ZipFile, name: str) -> str | None:
    """A root-level text file of the zip, or None when it is absent."""
    try:
        archive.getinfo(name)
    except KeyError:
        return None
    data = read_entry(archive, name)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        raise IntakeError(name, "not-utf8", f"is not UTF-8 text ({error})") from error


def check_policy(archive: zipfile.ZipFile) -> None:
    source = read_text(archive, POLICY)
    if source is None:
        nested = [n for n in archive.namelist() if n.endswith(f"/{POLICY}")]
        hint = f"; found {nested[0]}: zip the folder's contents, not the folder" if nested else ""
        raise IntakeError(POLICY, "policy-missing", f"the zip has no {POLICY} at its root{hint}")
    tree = parse_script(POLICY, source, "policy")
    if not defines_policy(tree):
        raise IntakeError(POLICY, "policy-class", "defines no top-level class Policy")


def check_train_script(archive: zipfile.ZipFile) -> bool:
    """True when the zip holds a ``train.py`` (Track 2) that compiles."""
    source = read_text(archive, TRAIN_SCRIPT)
    if source is None:
        return False
    parse_script(TRAIN_SCRIPT, source, "train")
    return True


def parse_script(name: str, source: str, rule: str) -> ast.Module:
    """The syntax tree of a submission's script; its rules are ``<rule>-syntax`` and
    ``<rule>-too-deep``."""
    try:
        tree = compile(source, name, "exec", flags=ast.PyCF_ONLY_AST, dont_inherit=True)
        compile(tree, name, "exec", dont_inherit=True)
    except SyntaxError as error:
        where = f"line {error.lineno}" + (f", column {error.offset}" if error.offset else "")
        raise IntakeError(name, f"{rule}-syntax", f"{error.msg} ({where})") from error
    except ValueError as error:
        raise IntakeError(name, f"{rule}-syntax", str(error)) from error
    except (RecursionError, MemoryError) as error:
        # A deeply nested expression overflows the compiler's stack: not a program we can check.
        raise IntakeError(
            name, f"{rule}-too-deep", f"nests expressions too deeply to compile ({error})"
        ) from error
    return tree


def defines_policy(tree: ast.Module) -> bool:
    """A top-level ``class Policy``, ``Policy = ...`` or ``from x import ... as Policy``."""
    for node in tree.body:
        if isinstance(node, ast.ClassDef) and node.name == "Policy":
            return True
        if isinstance(node, ast.Assign | ast.AnnAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            if any(isinstance(t, ast.Name) and t.id == "Policy" for t in targets):
                return True
        imported = isinstance(node, ast.ImportFrom | ast.Import)
        if imported and any((alias.asname or alias.name) == "Policy" for alias in node.names):
            return True
    return False


def load_interface(archive: zipfile.ZipFile) -> AgentInterface:
    text = read_text(archive, AGENT_YAML)
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


def load_explanation(archive: zipfile.ZipFile) -> str | None:
    text = read_text(archive, EXPLANATION)
    return None if text is None else text[:MAX_EXPLANATION_CHARS]
