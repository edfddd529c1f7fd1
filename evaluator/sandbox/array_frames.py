"""The act frames of ``observation_format: arrays`` (``docs/protocol.md``, "Arrays observations").

The layout of one agent's record (:class:`sim.observation_arrays.ObservationLayout`) is fixed by
its interface, so it is sent once (the ``layout`` message); each step then sends one binary frame:

    b"a" | uint32 agent count | uint32 record size | per agent: uint16 id length + UTF-8 id
         | one record per agent, in the same order

(integers big-endian, like the frame header; the records hold little-endian arrays). In an
episode the simulator writes each agent's record in place (``Simulation(arrays=True)``, an
:class:`sim.observation_record.ArraysObservation`) and its bytes go out as they are; an
observation dict (tests, tools) is encoded into a buffer kept from step to step. Never copied
or pickled.
"""

from __future__ import annotations

import struct

from sim.interface import AgentInterface
from sim.observation_arrays import ObservationEncoder, ObservationLayout
from sim.observation_record import ArraysObservation

TAG = b"a"  # the payload's first byte; a pickle's is 0x80
HEAD = struct.Struct(">II")
ID_SIZE = struct.Struct(">H")


class ArrayFrames:
    """Encodes each step's observations into an arrays act frame."""

    def __init__(self, interface: AgentInterface) -> None:
        self.layout = ObservationLayout(interface)
        # agent id -> its encoder (which follows that agent's paths from step to step) and the
        # record it writes into
        self._agents: dict[str, tuple[ObservationEncoder, bytearray]] = {}
        self._prefixes: dict[tuple[str, ...], bytes] = {}

    def frame(self, obs: dict[str, dict | ArraysObservation]) -> list[bytes | bytearray]:
        """The frame's payload for ``obs`` (agent id -> the simulator's arrays observation or an
        agent-interface dict), in parts; valid until the next call (the records are reused)."""
        records = []
        for agent_id, observation in obs.items():
            if isinstance(observation, ArraysObservation):
                records.append(observation.record)
                continue
            encoder, record = self._agents.get(agent_id) or self._agents.setdefault(
                agent_id, (ObservationEncoder(self.layout), bytearray(self.layout.size))
            )
            encoder.write(observation, record)
            records.append(record)
        return [self._prefix(tuple(obs)), *records]

    def _prefix(self, ids: tuple[str, ...]) -> bytes:
        # The same agents step after step: their prefix is built once.
        prefix = self._prefixes.get(ids)
        if prefix is None:
            parts = [TAG, HEAD.pack(len(ids), self.layout.size)]
            for agent_id in ids:
                encoded = agent_id.encode()
                parts += [ID_SIZE.pack(len(encoded)), encoded]
            prefix = self._prefixes[ids] = b"".join(parts)
        return prefix
