"""The warm agent parent (``main.py --zygote``): one per submission and evaluating process,
forking a fresh agent for every episode inside the same sandbox.

Standard library plus numpy only, no import of this project: it runs in the sandbox next to
``main.py``. It imports the runtime's libraries ``policy.py`` names (numpy, and whatever the
image ships), never the participant's own code: ``policy.py``, the submission's modules and its
dependency folder are imported by each child. So nothing a participant wrote runs in the parent,
and each episode's agent starts from the same state.

For each ``fork`` request the control socket carries three descriptors (``SCM_RIGHTS``): the
episode's protocol socket, its lifeline and its log. The child takes the protocol socket and the
log (fds 1 and 2); the parent keeps the lifeline and, when it reads anything or the evaluator
closes it, kills the child.

Each episode starts in state made new for it, not in state cleaned up after the last one: in an
isolating sandbox (the parent is its PID 1: Docker without ``--init``, ``bwrap --as-pid-1``) the
child enters namespaces of its own and mounts its own ``/tmp``, ``/dev/shm`` and ``/dev/mqueue``
(``confine.fresh_episode``), then installs the agents' seccomp filter, before any participant
code. Whatever it writes vanishes with its last process, and after it the parent kills every
process of the sandbox but itself (``kill(-1)`` from PID 1). The parent checks at start that a
child can do this (else it refuses to serve and the evaluator runs the submission cold), says
``{"type": "ready"}`` after each episode, then writes ``{"type": "exited", "code": ..., "oom":
...}`` on the lifeline. Being PID 1 also means that no signal from inside reaches it. Under the
unisolated ``process`` backend (a participant's local runs) it only kills the child's process
group. A child that cannot make its episode new exits before any agent code with
``UNCONFINED_EXIT`` and the parent retires: the evaluator starts another sandbox.
"""

from __future__ import annotations

import ast
import contextlib
import importlib
import importlib.machinery
import importlib.util
import json
import os
import pickle
import select
import signal
import socket
import sys
import time
import traceback

HEADER_SIZE = 4
FORK_FDS = 3  # protocol socket, lifeline, log
PR_SET_DUMPABLE = 4
# A child that could not make its episode new exits with this before any agent code runs.
UNCONFINED_EXIT = 125
PR_SET_NAME = 15
HOLDER_NAME = b"arena-holder"  # the process keeping an episode's namespaces (hold_namespaces)


class Zygote:
    def __init__(self, stream, args, runner) -> None:
        self.stream = stream
        self.args = args
        self.runner = runner  # the runner.py module: each child does its run_agent
        self.control = socket.socket(fileno=stream.read_fd)
        self.inbox = bytearray()
        self.fds: list[int] = []
        self.private = os.getpid() == 1  # its own pid namespace and /tmp: the sandbox is ours
        self.confine = runner.sibling_module(runner.CONFINE) if self.private else None

    def serve(self) -> int:
        started = time.perf_counter()
        # A submission that installs its own numpy gets it in its children: then the parent
        # loads neither numpy nor anything built on it (the runtime's numpy would win there).
        own_numpy = provides(self.args.deps, "numpy")
        hello = {
            "type": "hello",
            "protocol": self.runner.PROTOCOL_VERSION,
            "zygote": True,
            "python": sys.version.split()[0],
        }
        if not own_numpy:
            import numpy

            hello["numpy"] = numpy.__version__
        self.stream.send(hello)
        os.chdir("/")  # no library reads configuration from the submission folder here
        self.runner.sibling_module(self.runner.PACKED_WAYPOINTS)
        if not own_numpy:
            if self.args.observation_format not in self.runner.PLAIN_FORMATS:
                self.runner.sibling_module(self.runner.COMPAT)
            preload_runtime_modules(self.args)
        unconfined = self.probe_fresh_episode()
        if unconfined:
            self.stream.send({"type": "error", "kind": "sandbox", "message": unconfined})
            return 1
        # PID 1 ignores every signal it has no handler for, so only SIGCHLD (a wake-up) gets one;
        # Python's SIGINT handler would let a child end the parent with KeyboardInterrupt.
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        self.wake_r, self.wake_w = os.pipe()
        os.set_blocking(self.wake_w, False)
        signal.set_wakeup_fd(self.wake_w)
        signal.signal(signal.SIGCHLD, lambda *_: None)
        set_dumpable(False)  # a child may not ptrace or write the parent's memory
        self.stream.send({"type": "ready", "init_s": round(time.perf_counter() - started, 6)})
        while True:
            try:
                kind = self.receive()
            except EOFError:
                return 0
            fds, self.fds = self.fds, []
            if kind == "fork" and len(fds) == FORK_FDS:
                if not self.episode(*fds):
                    return 0  # retired
            else:
                for fd in fds:
                    os.close(fd)
                if kind == "close":
                    return 0

    def probe_fresh_episode(self) -> str | None:
        """Why a child could not make its episode new here (tried in a child that runs nothing
        else), or None when it can."""
        if not self.private:
            return None
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:
            code = 1
            try:
                self.confine.fresh_episode(self.args.scratch_bytes)
                code = 0
            except BaseException as error:
                with contextlib.suppress(BaseException):
                    print(f"confining an episode failed: {error!r}", file=sys.stderr, flush=True)
            finally:
                os._exit(code)
        _, status = os.waitpid(pid, 0)
        if os.waitstatus_to_exitcode(status) != 0:
            return "a forked agent cannot get namespaces of its own in this sandbox (see its log)"
        return None

    def receive(self) -> str:
        """The next control message's kind; descriptors that came with it land in ``self.fds``."""
        while True:
            if len(self.inbox) >= HEADER_SIZE:
                size = int.from_bytes(self.inbox[:HEADER_SIZE], "big")
                if len(self.inbox) >= HEADER_SIZE + size:
                    payload = bytes(self.inbox[HEADER_SIZE : HEADER_SIZE + size])
                    del self.inbox[: HEADER_SIZE + size]
                    kind, _ = pickle.loads(payload)
                    return kind
            data, fds, _, _ = socket.recv_fds(self.control, 1 << 16, FORK_FDS)
            if not data:
                raise EOFError
            self.inbox += data
            self.fds += fds

    def episode(self, data: int, lifeline: int, log: int) -> bool:
        """Fork one agent, wait for its end, clean up; False when the sandbox must retire."""
        oom_before = oom_kills()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:
            self.child(data, lifeline, log)
        os.close(data)
        os.close(log)
        code = self.supervise(pid, lifeline)
        # The episode's end first: its namespaces are torn down with the holder, in
        # reset_sandbox, while the evaluator already finishes the episode (it forks again only
        # after "ready").
        status = {"type": "exited", "code": code, "oom": oom_kills() > oom_before}
        payload = json.dumps(status).encode()
        with contextlib.suppress(OSError):
            os.write(lifeline, len(payload).to_bytes(HEADER_SIZE, "big") + payload)
        os.close(lifeline)
        try:
            clean = self.reset_sandbox(pid) and code != UNCONFINED_EXIT
        except Exception:
            traceback.print_exc()
            clean = False
        if clean:
            self.stream.send({"type": "ready"})
        return clean

    def child(self, data: int, lifeline: int, log: int) -> None:
        """The episode's agent: what ``main.py`` does without ``--zygote``. Never returns."""
        code = 1
        try:
            os.setsid()
            signal.set_wakeup_fd(-1)
            signal.signal(signal.SIGCHLD, signal.SIG_DFL)
            signal.signal(signal.SIGINT, signal.default_int_handler)
            set_dumpable(True)
            for fd in {self.control.fileno(), self.stream.write_fd, lifeline, *self.wakeups}:
                os.close(fd)
            self.control.detach()
            os.dup2(log, 1)
            os.dup2(log, 2)
            os.close(log)
            if self.confine is not None:
                try:
                    self.confine.fresh_episode(self.args.scratch_bytes)
                    hold_namespaces()
                except BaseException as error:
                    print(f"the sandbox could not make this episode new: {error!r}", flush=True)
                    code = UNCONFINED_EXIT
                    raise
            stream = self.runner.Stream(data, data)
            code = self.runner.run_agent(stream, self.args, time.perf_counter())
        except BaseException:
            code = UNCONFINED_EXIT if code == UNCONFINED_EXIT else 1
        finally:
            with contextlib.suppress(BaseException):
                sys.stderr.flush()
            os._exit(code)

    @property
    def wakeups(self) -> tuple[int, int]:
        return self.wake_r, self.wake_w

    def supervise(self, pid: int, lifeline: int) -> int:
        """Wait until the child ends or the evaluator asks (any byte, or closing the lifeline)
        for it to be killed; its exit code, negative for a signal, like ``Popen.returncode``."""
        poller = select.poll()
        poller.register(lifeline, select.POLLIN)
        poller.register(self.wake_r, select.POLLIN)
        while True:
            code = reap(pid)
            if code is not None:
                return code
            events = dict(poller.poll())
            if self.wake_r in events:
                with contextlib.suppress(BlockingIOError):
                    os.read(self.wake_r, 4096)
            if lifeline in events:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(pid, signal.SIGKILL)
                _, status = os.waitpid(pid, 0)
                return os.waitstatus_to_exitcode(status)

    def reset_sandbox(self, pid: int) -> bool:
        """End every process the episode left; False if that failed. Nothing else to undo: what
        the agent could write lived in its own namespaces, gone with its last process."""
        if not self.private:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(pid, signal.SIGKILL)
            return True
        with contextlib.suppress(ProcessLookupError):  # none left
            os.kill(-1, signal.SIGKILL)  # from PID 1: every process of the sandbox but this one
        while reap(None) is not None:
            pass
        return True


def hold_namespaces() -> None:
    """Fork a process that only keeps the episode's namespaces alive, so that tearing them down
    (several RCU grace periods: tens of ms on a busy host) happens when the parent kills it
    after the episode, not when the agent exits while the evaluator waits for its end. It holds
    no descriptor and runs nothing; an agent that kills it only brings the teardown back to its
    own exit. It is born with its name (set on this thread around the fork): named after the
    fork, an agent could meet it under this process's name first."""
    import ctypes

    prctl = ctypes.CDLL(None).prctl
    with open("/proc/thread-self/comm", "rb") as comm:
        own_name = comm.read().rstrip(b"\n")
    prctl(PR_SET_NAME, HOLDER_NAME, 0, 0, 0)
    pid = -1
    try:
        pid = os.fork()
    finally:
        if pid != 0:  # this process (the fork failed or made the holder): its own name back
            prctl(PR_SET_NAME, own_name, 0, 0, 0)
    if pid != 0:
        return
    try:
        os.closerange(0, os.sysconf("SC_OPEN_MAX"))
        while True:
            signal.pause()
    finally:
        os._exit(0)


def reap(pid: int | None) -> int | None:
    """Reap every ended child (PID 1 inherits the orphans); ``pid``'s exit code if it ended.
    With ``pid`` None: block until any child ends, None when there is none left."""
    if pid is None:
        try:
            _, status = os.waitpid(-1, 0)
        except ChildProcessError:
            return None
        return os.waitstatus_to_exitcode(status)
    code = None
    while True:
        try:
            ended, status = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return code
        if ended == 0:
            return code
        if ended == pid:
            code = os.waitstatus_to_exitcode(status)


def oom_kills() -> int:
    """The sandbox cgroup's count of OOM kills (v2 memory.events, v1 oom_control); 0 if unseen."""
    for path in ("/sys/fs/cgroup/memory.events", "/sys/fs/cgroup/memory/memory.oom_control"):
        with contextlib.suppress(OSError, ValueError), open(path) as counters:
            for line in counters:
                name, _, value = line.partition(" ")
                if name == "oom_kill":
                    return int(value)
    return 0


def set_dumpable(on: bool) -> None:
    with contextlib.suppress(ImportError, OSError, AttributeError):
        import ctypes

        ctypes.CDLL(None).prctl(PR_SET_DUMPABLE, int(on), 0, 0, 0)


def provides(folder: str | None, name: str) -> bool:
    """Whether the dependency ``folder`` holds the top-level module ``name``."""
    if not folder:
        return False
    return importlib.machinery.PathFinder.find_spec(name, [folder]) is not None


def preload_runtime_modules(args) -> None:
    """Import the top-level modules ``policy.py`` imports that the runtime provides: found
    neither in the submission folder nor in its dependency folder (those are the participant's
    and run only in the children). A library that fails here is left to the child to report."""
    private = [args.submission, *([args.deps] if args.deps else [])]
    try:
        with open(os.path.join(args.submission, "policy.py"), "rb") as source:
            tree = ast.parse(source.read())
    except (OSError, SyntaxError, ValueError):
        return
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name.partition(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.partition(".")[0])
    for name in sorted(names - set(sys.modules)):
        if importlib.machinery.PathFinder.find_spec(name, private) is not None:
            continue  # the participant's own module, or one that shadows the runtime's
        with contextlib.suppress(Exception):
            if importlib.util.find_spec(name) is not None:
                importlib.import_module(name)
