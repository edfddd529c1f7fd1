"""A :class:`learn.session.SimulatorSession` in a child process, driven over a pipe.

libsumo holds one simulation per process, so an environment that cannot simulate in its own
process (another one already does: ``learn.simulators.open_simulator``) owns a child of its own
(started with ``subprocess``, which also works inside the daemonic workers of
``AsyncVectorEnv``). Observations travel as records (:mod:`sim.observation_arrays`).

Frames both ways are a 4-byte big-endian length and a pickle: both ends are our own code.
"""

from __future__ import annotations

import os
import pickle
import struct
import subprocess
import sys
import traceback
from pathlib import Path
from typing import Any, BinaryIO

from arena.child_env import HOST_TOOL_VARIABLES, child_environment
from arena.errors import InfrastructureError
from learn.protocol import Config, Reply
from learn.record_views import RecordViews
from learn.session import SimulatorSession
from sim.observation_arrays import ObservationLayout

HEADER = struct.Struct(">I")
PROJECT_ROOT = Path(__file__).resolve().parents[1]


class SimulatorError(InfrastructureError, RuntimeError):
    """The simulator child failed (a SUMO error, or the child died)."""


# --- the parent's side -----------------------------------------------------------------------


class SimulatorProcess:
    """A child process holding one simulator; :meth:`call` sends a command and waits."""

    def __init__(self, config: Config) -> None:
        self._views = RecordViews(ObservationLayout(config.interface))
        # The child must import the same code as this process (a worktree before an install).
        path = os.pathsep.join([str(PROJECT_ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])
        env = child_environment({"PYTHONPATH": path}, inherit=HOST_TOOL_VARIABLES)
        self._child = subprocess.Popen(
            [sys.executable, "-m", "learn.worker"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            env=env,
        )
        self.call("configure", config)

    def reset(self, scenario_dir: str, seed: int | None) -> Reply:
        return self.call("reset", (scenario_dir, seed))

    def step(self, actions: dict[str, Any]) -> Reply:
        return self.call("step", actions)

    def call(self, kind: str, body: Any = None) -> Any:
        if self._child.poll() is not None:
            raise SimulatorError(f"simulator process exited with code {self._child.returncode}")
        try:
            _write(self._child.stdin, (kind, body))
            status, value = _read(self._child.stdout)
        except (BrokenPipeError, EOFError, struct.error) as error:
            raise SimulatorError(f"simulator process died: {error}") from error
        if status == "error":
            raise SimulatorError(value)
        if isinstance(value, Reply):
            arrays = self._views.arrays  # views of the freshly unpickled records
            value.observations = {k: arrays(v) for k, v in value.observations.items()}
            value.terminal = {k: arrays(v) for k, v in value.terminal.items()}
        return value

    def cpu_seconds(self) -> float:
        """CPU time [s] the child has used so far (user + system; Linux ``/proc``)."""
        fields = Path(f"/proc/{self._child.pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def close(self) -> None:
        if self._child.poll() is None:
            try:
                _write(self._child.stdin, ("close", None))
                self._child.stdin.close()
                self._child.wait(timeout=10)
            except (BrokenPipeError, OSError, subprocess.TimeoutExpired):
                self._child.kill()
                self._child.wait()
        for stream in (self._child.stdin, self._child.stdout):
            if stream is not None and not stream.closed:
                stream.close()


def _write(stream: BinaryIO, message: Any) -> None:
    payload = pickle.dumps(message, protocol=5)
    stream.write(HEADER.pack(len(payload)) + payload)
    stream.flush()


def _read(stream: BinaryIO) -> Any:
    header = stream.read(HEADER.size)
    if len(header) < HEADER.size:
        raise EOFError("no reply")
    (size,) = HEADER.unpack(header)
    payload = stream.read(size)
    if len(payload) < size:
        raise EOFError("truncated reply")
    return pickle.loads(payload)


# --- the child's side ------------------------------------------------------------------------


def main() -> int:
    # The protocol gets private copies of stdin/stdout; fd 1 then points at stderr, so SUMO's
    # and anyone's prints cannot corrupt a frame.
    reader = os.fdopen(os.dup(0), "rb")
    writer = os.fdopen(os.dup(1), "wb")
    devnull = os.open(os.devnull, os.O_RDONLY)
    os.dup2(devnull, 0)
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    session: SimulatorSession | None = None
    while True:
        try:
            kind, body = _read(reader)
        except EOFError:
            break
        try:
            if kind == "configure":
                session = SimulatorSession(body, packed=True)
                result: Any = None
            elif kind == "reset":
                result = session.reset(*body)
            elif kind == "step":
                result = session.step(body)
            elif kind == "close":
                _write(writer, ("ok", None))
                break
            else:
                raise ValueError(f"unknown command {kind!r}")
        except Exception as error:
            _write(writer, ("error", f"{error}\n{traceback.format_exc()[-4000:]}"))
            continue
        _write(writer, ("ok", result))
    if session is not None:
        session.close()
    return 0


if __name__ == "__main__":
    # Run the imported module's main, so that this module's names pickle as `learn.worker`, not
    # `__main__`, which the parent could not load.
    from learn import worker

    sys.exit(worker.main())
