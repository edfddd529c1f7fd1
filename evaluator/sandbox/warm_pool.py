"""The warm agents of one evaluating process (``arena evaluate``, or a service worker).

Each episode leases a :class:`~evaluator.sandbox.warm.WarmAgent` of its submission for itself:
one zygote serves one episode at a time, so two episodes in parallel get two. A lease returns
it; it closes when it has been idle for ``warm_agent_idle_s``, when the evaluation that used it
ends (:meth:`WarmAgents.close`), when the worker stops (``server/worker/tasks.py``) or at exit.
A submission whose zygote cannot start is run cold (a new sandbox per episode) in this process.
"""

from __future__ import annotations

import atexit
import logging
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from functools import lru_cache
from pathlib import Path

from arena.config import SandboxKind, SandboxSettings
from arena.errors import SandboxUnavailable
from evaluator.sandbox.warm import KILL_WAIT_S, ForkedAgent, WarmAgent

log = logging.getLogger(__name__)

# (the submission zip's sha256, its trained model folder or None, sandbox kind, the CPUs it runs
# on or None): by content, so that a submission prepared again (into another folder) finds its
# warm agent, and one prepared elsewhere never borrows another's. The folders a warm agent binds
# are never changed under it (a worker prepares each zip once, into a folder named after its
# digest). A zygote's CPUs are its sandbox's (Docker's cpuset is set at creation), so each
# job's episodes fork from a zygote on the job's CPUs (evaluator.sandbox.placement).
Key = tuple[str, Path | None, SandboxKind, tuple[int, ...] | None]


class WarmAgents:
    def __init__(self, labels: dict[str, str] | None = None) -> None:
        self._labels = dict(labels or {})  # on every zygote's sandbox
        self._lock = threading.Lock()
        self._idle: dict[Key, list[WarmAgent]] = {}
        self._leased: list[ForkedAgent] = []
        self._cold: set[Key] = set()  # submissions whose zygote would not start

    @contextmanager
    def lease(
        self,
        submission,
        kind: SandboxKind,
        labels: dict[str, str],
        config: SandboxSettings,
        data_dir: Path,
        cpus: tuple[int, ...] | None = None,
    ) -> Iterator[ForkedAgent | None]:
        """A freshly forked agent of ``submission`` for one episode, on ``cpus`` (the job's;
        None: any), or None when this submission runs cold. Raises nothing of the zygote's: it
        falls back to cold."""
        # A retrained model is another agent: it gets a zygote of its own.
        key = (submission.sha256, submission.model_dir, kind, cpus)
        self.close_idle(config.warm_agent_idle_s)
        warm = self._take(key, submission, config, data_dir)
        if warm is None:
            yield None
            return
        try:
            agent = warm.fork(config, labels)
        except SandboxUnavailable as error:
            log.warning("warm agent lost, this episode starts cold: %s", error)
            warm.close()
            yield None
            return
        with self._lock:
            self._leased.append(agent)
        try:
            yield agent
        finally:
            with self._lock:
                self._leased.remove(agent)
            agent.close()
            self._give_back(key, warm)

    def kill(self, labels: dict[str, str]) -> int:
        """Kill the leased agents carrying all ``labels``; how many."""
        wanted = labels.items()
        with self._lock:
            chosen = [a for a in self._leased if wanted <= a.labels.items()]
        for agent in chosen:
            agent.kill()
        return len(chosen)

    def close(self, sha256: str | None = None, model_dir: Path | None = None) -> None:
        """Close the idle warm agents of the submission whose zip has ``sha256`` and of those
        bound to the trained output ``model_dir`` (every one without either)."""

        def chosen(key: Key) -> bool:
            return (sha256 is None or key[0] == sha256) and (
                model_dir is None or key[1] == model_dir
            )

        with self._lock:
            keys = [k for k in self._idle if chosen(k)]
            closing = [warm for key in keys for warm in self._idle.pop(key)]
            self._cold -= {k for k in self._cold if chosen(k)}
        for warm in closing:
            warm.close()

    def close_idle(self, idle_s: float) -> None:
        cutoff = time.monotonic() - idle_s
        with self._lock:
            closing = [w for ws in self._idle.values() for w in ws if w.last_used < cutoff]
            for key, ws in self._idle.items():
                self._idle[key] = [w for w in ws if w.last_used >= cutoff]
        for warm in closing:
            warm.close()

    def _take(
        self, key: Key, submission, config: SandboxSettings, data_dir: Path
    ) -> WarmAgent | None:
        while True:
            with self._lock:
                if key in self._cold:
                    return None
                idle = self._idle.get(key, [])
                warm = idle.pop() if idle else None
            if warm is None:
                break
            if warm.settled(KILL_WAIT_S):
                return warm
            warm.close()
        try:
            return WarmAgent.start(
                submission, key[2], config, data_dir, labels=self._labels, cpus=key[3]
            )
        except SandboxUnavailable as error:
            log.warning("no warm agent for %s, its episodes start cold: %s", key[0], error)
            with self._lock:
                self._cold.add(key)
            return None

    def _give_back(self, key: Key, warm: WarmAgent) -> None:
        """Back to the pool at once: the zygote ends the episode (kills what is left, tears down
        its namespaces) while the evaluator goes on; the next lease waits for its ``ready``."""
        warm.settling = True
        with self._lock:
            self._idle.setdefault(key, []).append(warm)


@lru_cache(maxsize=1)
def warm_agents() -> WarmAgents:
    """This process's warm agents, closed at exit."""
    agents = WarmAgents()
    atexit.register(agents.close)
    return agents
