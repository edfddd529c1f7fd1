"""Names and seeds of the scenarios of a suite, shared by the suite builder
(:mod:`scenarios.suites`) and the scenario sources it draws from."""

from __future__ import annotations

import hashlib

from scenarios.generators import Spec


def derive_seed(suite: str, suite_seed: int, *parts: object) -> int:
    """A 31-bit seed (SUMO takes int32) from a domain-separated hash."""
    text = "/".join(["driving-arena", suite, str(suite_seed), *map(str, parts)])
    return int.from_bytes(hashlib.sha256(text.encode()).digest()[:4], "big") & 0x7FFFFFFF


def seed_fingerprint(seed: int) -> str:
    return hashlib.sha256(f"driving-arena/seed-fingerprint/{seed}".encode()).hexdigest()[:16]


def scenario_id(suite: str, index: int, spec: Spec) -> str:
    parts = [f"{suite[0]}{index:03d}"]
    if not spec.variant.startswith(spec.family.value):
        parts.append(spec.family.value)
    parts.append(spec.variant)
    if spec.volume:
        parts.append(spec.volume)
    if spec.agents > 1:
        parts.append(f"{spec.agents}agents")
    return "_".join(parts)
