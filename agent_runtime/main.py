"""The agent runtime's entry point: the one program started inside the sandbox.

It imports the participant's ``policy.py`` (working directory = the submission folder), builds
``Policy()`` and then answers the evaluator over a framed protocol until told to close. The
protocol is described in ``docs/protocol.md``; in short, every message is a 4-byte big-endian
length followed by the payload. Evaluator -> agent payloads are pickles (the agent may trust its
host), except the binary ``act`` frames of ``observation_format: arrays``; agent -> evaluator
payloads are UTF-8 JSON (the host trusts nothing the agent sends).

Standard library plus numpy only, and no import of this project: the sandbox holds just this
folder (``agent_runtime/``), the submission and its dependency folder.

The protocol stream is a private copy of the original stdout (or a unix socket with ``--socket``);
file descriptor 1 is pointed at stderr before the policy is imported, so a policy's ``print`` and
anything its libraries write to stdout land in the log, never in the protocol.

With ``--zygote`` it is a warm parent instead (``docs/protocol.md``, "Warm agents"): it
imports the runtime's libraries once and, for each episode, forks a child that receives that
episode's channels over the control socket, imports ``policy.py`` and serves it as above. The
zygote itself never runs the participant's code.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import pickle
import socket
import struct
import sys
import time
import traceback

PROTOCOL_VERSION = 1
COMPAT = "smarts_compat"  # observation converters, next to this file
ZYGOTE = "zygote"  # the warm parent of --zygote, next to this file
CONFINE = "confine"  # each warm episode's fresh namespaces and seccomp filter, next to this file
PACKED_WAYPOINTS = "packed_waypoints"  # act messages' waypoint paths to dicts, next to this file
SIBLING_PREFIX = "_arena_runtime_"  # sys.modules key of each module above (sibling_module)
HEADER = struct.Struct(">I")
MAX_INCOMING_BYTES = 1 << 30
# Formats the policy gets as the protocol delivers them; any other is converted (COMPAT).
PLAIN_FORMATS = ("native", "arrays")
# The libraries whose versions decide what an agent computes, by module name: each one the agent
# has imported is named with its version in the ready message (the results manifest's agent_stack).
NUMERICAL_STACK = (
    "numpy", "scipy", "torch", "tensorflow", "jax", "sklearn", "pandas", "numba", "cv2",
    "gym", "gymnasium", "stable_baselines3",
)  # fmt: skip
# An arrays act frame: b"a", then agent count and record size (a pickle starts with 0x80).
ARRAYS_TAG = ord("a")
ARRAYS_HEAD = struct.Struct(">BII")
ID_SIZE = struct.Struct(">H")


class Closed(Exception):
    """The evaluator closed the stream."""


class Stream:
    """Length-prefixed frames over two file descriptors (the same one for a socket)."""

    def __init__(self, read_fd: int, write_fd: int) -> None:
        self.read_fd = read_fd
        self.write_fd = write_fd
        # Frames are read into one reused buffer, grown when a bigger one comes; each read takes
        # what has arrived, so a frame and its header usually come in one system call.
        self.buffer = bytearray(1 << 16)
        self.start = 0  # the bytes read and not yet taken are buffer[start:end]
        self.end = 0

    def read_exact(self, size: int) -> memoryview:
        """The next ``size`` bytes: a view of the buffer, valid until the next read."""
        if self.end - self.start < size:
            self.make_room(size)
            view = memoryview(self.buffer)
            while self.end - self.start < size:
                received = os.readv(self.read_fd, [view[self.end :]])
                if received == 0:
                    raise Closed
                self.end += received
        at = self.start
        self.start += size
        return memoryview(self.buffer)[at : at + size]

    def make_room(self, size: int) -> None:
        """Room for ``size`` bytes from ``start``: the bytes not yet taken move to the front, of
        a new buffer when this one is too small (views of the old one stay valid)."""
        if self.start == self.end:
            self.start = self.end = 0  # every frame at the front: the same memory every step
        if self.start + size <= len(self.buffer):
            return
        pending = self.buffer[self.start : self.end]
        if size > len(self.buffer):
            self.buffer = bytearray(size)
        self.buffer[: len(pending)] = pending
        self.start, self.end = 0, len(pending)

    def receive(self) -> tuple[str, object]:
        """A message's kind and body; an arrays act frame is ``("arrays", payload)``, a view of
        the reused buffer, valid until the next receive. An act message's observations come
        with their waypoint paths as dicts, however they travelled."""
        (size,) = HEADER.unpack(self.read_exact(HEADER.size))
        if size > MAX_INCOMING_BYTES:
            raise Closed
        payload = self.read_exact(size)
        if size and payload[0] == ARRAYS_TAG:
            return "arrays", payload
        kind, body = pickle.loads(payload)
        if kind == "act":
            sibling_module(PACKED_WAYPOINTS).expand_observations(body)
        return kind, body

    def send(self, message: dict) -> None:
        payload = ENCODER.encode(message).encode()
        data = memoryview(HEADER.pack(len(payload)) + payload)
        while data:
            data = data[os.write(self.write_fd, data) :]


def to_json(value: object) -> object:
    """numpy values a policy returns (arrays, float32 scalars) become plain JSON values."""
    tolist = getattr(value, "tolist", None)
    if tolist is None:
        raise TypeError(f"{type(value).__name__} is not a number, list or dict")
    return tolist()


# Made once: json.dumps with options builds an encoder per call.
ENCODER = json.JSONEncoder(default=to_json, separators=(",", ":"))


def error_message(error: BaseException) -> dict:
    kind = "memory" if isinstance(error, MemoryError) else "exception"
    return {
        "type": "error",
        "kind": kind,
        "message": f"{type(error).__name__}: {error}",
        "traceback": "".join(traceback.format_exception(error)),
    }


def open_stream(socket_path: str | None) -> Stream:
    """Take the protocol channel and point fds 0 and 1 away from it."""
    if socket_path:
        channel = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        channel.connect(socket_path)
        fd = os.dup(channel.fileno())
        channel.close()
        stream = Stream(fd, fd)
    else:
        stream = Stream(os.dup(0), os.dup(1))
    devnull = os.open(os.devnull, os.O_RDONLY)
    os.dup2(devnull, 0)
    os.close(devnull)
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    return stream


def put_submission_first(submission: str, deps: str | None) -> None:
    """The submission folder, then its installed requirements, ahead of everything the sandbox
    ships: done before the runtime imports numpy, so a pinned numpy is the one loaded."""
    for folder in reversed([submission, *([deps] if deps else [])]):
        if folder not in sys.path:
            sys.path.insert(0, folder)


def load_policy(submission: str, deps: str | None) -> tuple[object, object]:
    """The policy object and its module (which may define ``submitted_wrappers``)."""
    os.chdir(submission)
    put_submission_first(submission, deps)
    spec = importlib.util.spec_from_file_location("policy", os.path.join(submission, "policy.py"))
    module = importlib.util.module_from_spec(spec)
    sys.modules["policy"] = module
    spec.loader.exec_module(module)
    policy = module.Policy()
    if not callable(getattr(policy, "act", None)):
        raise TypeError("Policy has no act(self, obs) method")
    return policy, module


def checked_act(act, obs: dict) -> dict:
    actions = act(obs)
    if not isinstance(actions, dict):
        raise TypeError(
            f"Policy.act must return a dict of agent id -> action, got {type(actions).__name__}"
        )
    return actions


class ArrayObservations:
    """Reads arrays act frames (``docs/protocol.md``, "Arrays observations") with the layout
    the evaluator sent once: each agent's record is copied out of the frame into a record of its
    own, whose arrays are views of it, so a policy may keep them. The records and their views
    for the next frame are built ahead (:meth:`prepare`, while the evaluator steps the
    simulation), so a frame only copies its records in."""

    def __init__(self, layout: dict) -> None:
        import numpy

        self.size = layout["size"]
        self.ndarray = numpy.ndarray
        # The whole record as one structured value, a field per leaf ("group/name"): a leaf's
        # view is then a field lookup, about a third of the time of making each view anew.
        fields = {
            "/".join(path): (dtype, tuple(shape), offset)
            for path, dtype, shape, offset in layout["leaves"]
        }
        self.record_type = numpy.dtype(
            {
                "names": list(fields),
                "formats": [(dtype, shape) for dtype, shape, _ in fields.values()],
                "offsets": [offset for _, _, offset in fields.values()],
                "itemsize": self.size,
            }
        )
        # (key, field, None) for an array, (key, None, [(name, field)]) for a dict of arrays
        # (the layout nests two deep), in the layout's order.
        self.plan = []
        groups: dict[str, list] = {}
        for path, *_ in layout["leaves"]:
            field = "/".join(path)
            if len(path) == 1:
                self.plan.append((path[0], field, None))
                continue
            group, name = path
            if group not in groups:
                groups[group] = []
                self.plan.append((group, None, groups[group]))
            groups[group].append((name, field))
        self.ready: list[tuple[bytearray, dict]] = []  # unused records and their observations
        self.agents = 0  # how many agents the last frame had: the next one likely has as many

    def decode(self, payload: memoryview) -> dict:
        _, count, size = ARRAYS_HEAD.unpack_from(payload)
        if size != self.size:
            raise ValueError(f"an arrays frame of {size}-byte records, the layout has {self.size}")
        at = ARRAYS_HEAD.size
        ids = []
        for _ in range(count):
            (length,) = ID_SIZE.unpack_from(payload, at)
            at += ID_SIZE.size
            ids.append(str(payload[at : at + length], "utf-8"))
            at += length
        if len(payload) != at + count * size:
            raise ValueError(f"an arrays frame of {len(payload)} bytes, not {at + count * size}")
        obs = {}
        for agent_id in ids:
            record, obs[agent_id] = self.ready.pop() if self.ready else self.observation()
            record[:] = payload[at : at + size]  # the same size: its views stay valid
            at += size
        self.agents = count
        return obs

    def prepare(self) -> None:
        """Build records and their observations for as many agents as the last frame had."""
        while len(self.ready) < self.agents:
            self.ready.append(self.observation())

    def observation(self) -> tuple[bytearray, dict]:
        """A new record (zeros) and the observation dict of its views."""
        record = bytearray(self.size)
        whole = self.ndarray((), self.record_type, record)
        obs = {}
        for key, field, group in self.plan:
            if group is None:
                obs[key] = whole[field]
            else:
                obs[key] = {name: whole[field] for name, field in group}
        return record, obs


def load_adapter(observation_format: str, action_space: str, options: dict):
    """The converter for ``observation_format`` (None for ours); ``options``: agent.yaml's."""
    if observation_format in PLAIN_FORMATS:
        return None
    module = sibling_module(COMPAT)
    if observation_format != module.FORMAT:
        raise ValueError(f"unknown observation_format {observation_format!r}")
    return module.SmartsAdapter(
        action_space, int(options.get("img_pixels", 256)), float(options.get("img_meters", 64.0))
    )


def sibling_module(name: str):
    """``<name>.py`` from beside this file (the sandbox mounts it there; -I keeps this folder off
    sys.path), loaded once per process: a zygote's children find it loaded. It is kept under a
    name of ours (:data:`SIBLING_PREFIX`), so that a submission's own module of the same name is
    neither taken for it nor replaced by it."""
    key = SIBLING_PREFIX + name
    module = sys.modules.get(key)
    if module is None:
        here = os.path.dirname(os.path.abspath(__file__))
        spec = importlib.util.spec_from_file_location(key, os.path.join(here, f"{name}.py"))
        module = importlib.util.module_from_spec(spec)
        sys.modules[key] = module
        try:
            spec.loader.exec_module(module)
        except BaseException:
            del sys.modules[key]
            raise
    return module


def serve(stream: Stream, policy: object, adapter=None) -> None:
    """Answer act, reset and close messages with ``policy`` until close."""
    reset = getattr(policy, "reset", None)
    act = policy.act
    arrays = None  # the reader of arrays act frames, once the layout came
    while True:
        try:
            kind, body = stream.receive()
        except Closed:
            return
        if kind == "layout":
            arrays = ArrayObservations(body)
        elif kind in ("act", "arrays"):
            try:
                if kind == "arrays":
                    obs = arrays.decode(body)
                else:
                    obs = adapter.observations(body) if adapter else body
                # An exception ends every agent of the episode: the policy drives them all
                # (docs/protocol.md, "An exception in act").
                actions = checked_act(act, obs)
                if adapter:
                    actions = adapter.actions(actions)
                stream.send({"type": "actions", "actions": actions})
                if kind == "arrays":
                    arrays.prepare()  # after the answer: off the round trip
            except BaseException as error:
                stream.send(error_message(error))
                return
        elif kind == "reset":
            try:
                if adapter:
                    adapter.reset()
                if reset is not None:
                    reset()
                stream.send({"type": "done"})
            except BaseException as error:
                stream.send(error_message(error))
                return
        elif kind == "close":
            stream.send({"type": "done"})
            return


class WrappedServer:
    """Serves a competition-kit policy (``observation_format: smarts2022`` and a policy module
    with ``submitted_wrappers()``) the way the 2022 evaluation ran it: its wrappers around an
    environment whose ``step`` is our act exchange, and the loop ``obs = env.reset()``, then
    ``obs, _, dones, _ = env.step(policy.act(obs))`` until ``dones["__all__"]``."""

    def __init__(self, stream: Stream, policy, adapter, wrappers, options: dict, action_space):
        self.stream = stream
        self.policy = policy
        self.adapter = adapter
        self.wrappers = wrappers
        self.options = options
        self.action_space = action_space
        self.pending = None  # the first observations of an episode, read before env.reset()
        self.agent_ids: list[str] = []  # every agent of the episode, as the last reset named them
        self.compat = sibling_module(COMPAT)

    def serve(self) -> None:
        env = None
        try:
            while True:
                self.pending = self.first()
                if env is None:  # wrappers learn the agent ids at construction, as in SMARTS
                    interface = self.compat.agent_interface(self.options, self.action_space)
                    # Every agent of the episode, those that start later too (SMARTS's
                    # agent_specs); the first observations where a reset named none.
                    agents = dict.fromkeys(self.agent_ids or self.pending, interface)
                    env = self.compat.SandboxEnv(self, agents, self.options)
                    for wrap in self.wrappers:
                        env = wrap(env)
                observations = env.reset()
                while True:
                    observations, _, dones, _ = env.step(self.policy.act(observations))
                    if dones.get("__all__"):
                        break
        except Closed:
            return
        except BaseException as error:
            self.stream.send(error_message(error))

    def first(self) -> dict:
        """The next episode's first observations (``reset`` and ``close`` answered on the way)."""
        while True:
            kind, body = self.stream.receive()
            if kind == "act":
                return self.adapter.observations(body)
            self.episode_end(kind, body)

    def episode_end(self, kind: str, body: object) -> None:
        if kind == "close":
            self.stream.send({"type": "done"})
            raise Closed
        if kind == "reset":
            if isinstance(body, dict) and isinstance(body.get("agents"), list):
                self.agent_ids = [str(agent_id) for agent_id in body["agents"]]
            self.adapter.reset()
            reset = getattr(self.policy, "reset", None)
            if reset is not None:
                reset()
            self.stream.send({"type": "done"})

    # SandboxEnv's side of the exchange.

    def answer(self, actions) -> None:
        if not isinstance(actions, dict):
            raise TypeError(
                "the wrapped environment's step needs a dict of agent id -> action, "
                f"got {type(actions).__name__}"
            )
        self.stream.send({"type": "actions", "actions": self.adapter.actions(actions)})

    def first_observations(self) -> dict:
        pending, self.pending = self.pending, None
        return pending if pending is not None else self.first()

    def next(self) -> dict:
        kind, body = self.stream.receive()
        if kind == "act":
            return self.adapter.observations(body)
        self.episode_end(kind, body)
        raise self.compat.EpisodeOver


def imported_stack() -> dict[str, str]:
    """Python's version and that of each :data:`NUMERICAL_STACK` module imported so far, as
    loaded (a submission's own numpy, not the runtime's)."""
    stack = {"python": sys.version.split()[0]}
    for name in NUMERICAL_STACK:
        module = sys.modules.get(name)
        if module is not None:
            stack[name] = str(getattr(module, "__version__", "unknown"))
    return stack


def run_agent(stream: Stream, args: argparse.Namespace, started: float) -> int:
    """One agent's life on ``stream``: hello, build the policy, ready, serve until close.

    Hello comes before anything of the submission is read or imported: the evaluator charges
    whatever ends the sandbox before hello to itself and everything after it to the team
    (docs/protocol.md, "Whose failure it is"), so a module of the submission that shadows one
    the runtime imports must not run before it."""
    stream.send({"type": "hello", "protocol": PROTOCOL_VERSION, "python": sys.version.split()[0]})
    put_submission_first(args.submission, args.deps)
    options = json.loads(args.interface or "{}")
    try:
        adapter = load_adapter(args.observation_format, args.action_space, options)
        policy, module = load_policy(args.submission, args.deps)
        hook = getattr(module, "submitted_wrappers", None) if adapter else None
        wrappers = list(hook()) if callable(hook) else None
    except BaseException as error:
        stream.send(error_message(error))
        return 1
    init_s = round(time.perf_counter() - started, 6)
    stream.send({"type": "ready", "init_s": init_s, "stack": imported_stack()})
    if wrappers is not None:
        WrappedServer(stream, policy, adapter, wrappers, options, args.action_space).serve()
    else:
        serve(stream, policy, adapter)
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--submission", required=True)
    parser.add_argument("--deps")
    parser.add_argument("--socket", help="unix socket to connect to instead of stdin/stdout")
    parser.add_argument("--observation-format", default="native", help="agent.yaml's choice")
    parser.add_argument("--action-space", default="TargetPose", help="agent.yaml's choice")
    parser.add_argument("--interface", help="agent.yaml's options as JSON (smarts2022)")
    parser.add_argument("--zygote", action="store_true", help="fork one agent per episode")
    parser.add_argument(
        "--scratch-bytes", type=int, default=64 << 20, help="each forked agent's /tmp, /dev/shm"
    )
    args = parser.parse_args()
    started = time.perf_counter()
    stream = open_stream(args.socket)
    if args.zygote:
        return sibling_module(ZYGOTE).Zygote(stream, args, sys.modules[__name__]).serve()
    return run_agent(stream, args, started)


if __name__ == "__main__":
    sys.exit(main())
