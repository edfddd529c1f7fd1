"""A policy that looks for marks an earlier episode may have left in every kind of writable state
it can reach, then leaves its own (test data: copied into a submission, run in a sandbox).

Each ``act`` answers one number per kind of state: 1.0 where a mark is found. The first act of an
episode looks before marking, the second after, so the test knows every probe can see a mark.
"""

import contextlib
import ctypes
import os
import socket
import time

MARK = b"arena-mark"
SYSV_KEY = 0x41524E41
IPC_CREAT = 0o1000
O_CREAT, O_RDWR, O_RDONLY = 0o100, 0o2, 0
KINDS = (
    "tmp file",
    "tmp after chmod 000",
    "dev/shm file",
    "dev file",
    "dev/mqueue file",
    "home file",
    "sysv shm",
    "sysv msg",
    "sysv sem",
    "posix mqueue",
    "abstract socket",
    "keyring",
    "environment",
    "process",
    "cgroup memory peak",
    "hostname",
)
PEAK_FILES = (
    "/sys/fs/cgroup/memory.peak",
    "/sys/fs/cgroup/memory/memory.max_usage_in_bytes",
)
BALLAST_BYTES = 200 * 1024**2

libc = ctypes.CDLL(None, use_errno=True)
try:
    librt = ctypes.CDLL("librt.so.1", use_errno=True)
except OSError:
    librt = libc


def exists(path):
    try:
        return os.path.exists(path)
    except OSError:
        return False


def can_connect(name):
    probe = socket.socket(socket.AF_UNIX)
    try:
        probe.connect(name)
        return True
    except OSError:
        return False
    finally:
        probe.close()


def keyring_has_mark():
    # request_key("user", "arena-mark", NULL, 0): found in the process's keyrings
    return libc.syscall(249, b"user", MARK, None, 0) >= 0


def peak_bytes():
    for path in PEAK_FILES:
        try:
            with open(path) as counter:
                return int(counter.read())
        except (OSError, ValueError):
            continue
    return 0


def command_name(pid):
    try:
        with open(f"/proc/{pid}/comm") as comm:
            return comm.read().strip()
    except OSError:
        return ""


def others():
    """Processes but this one, its parent and the sandbox's init, and the runtime's holder of
    this episode's namespaces (agent_runtime/zygote.py hold_namespaces)."""
    mine = {os.getpid(), os.getppid(), 1}
    return [
        p
        for p in os.listdir("/proc")
        if p.isdigit() and int(p) not in mine and command_name(p) != "arena-holder"
    ]


def look():
    home = os.path.expanduser("~")
    return [
        exists("/tmp/mark"),
        exists("/tmp/locked/mark"),
        exists("/dev/shm/mark"),
        exists("/dev/mark"),
        exists("/dev/mqueue/mark"),
        exists(os.path.join(home, ".mark")),
        libc.shmget(SYSV_KEY, 0, 0) >= 0,
        libc.msgget(SYSV_KEY, 0) >= 0,
        libc.semget(SYSV_KEY, 0, 0) >= 0,
        librt.mq_open(b"/arena-mark", O_RDONLY) >= 0,
        can_connect("\0arena-mark"),
        keyring_has_mark(),
        os.environ.get("ARENA_MARK") == "1",
        bool(others()),
        peak_bytes() >= BALLAST_BYTES,
        socket.gethostname() == "arena-mark",
    ]


def attempt(action):
    with contextlib.suppress(OSError):
        action()


def write(path, text="x"):
    with open(path, "w") as file:
        file.write(text)


def leave_marks():
    attempt(lambda: write("/tmp/mark"))
    attempt(lambda: os.makedirs("/tmp/locked", exist_ok=True))
    attempt(lambda: write("/tmp/locked/mark"))
    attempt(lambda: write("/dev/shm/mark"))
    attempt(lambda: write("/dev/mark"))
    attempt(lambda: write("/dev/mqueue/mark"))
    attempt(lambda: write(os.path.join(os.path.expanduser("~"), ".mark")))
    libc.shmget(SYSV_KEY, 4096, IPC_CREAT | 0o600)
    libc.msgget(SYSV_KEY, IPC_CREAT | 0o600)
    libc.semget(SYSV_KEY, 1, IPC_CREAT | 0o600)
    librt.mq_open(b"/arena-mark", O_CREAT | O_RDWR, 0o600, None)
    # add_key("user", "arena-mark", "x", 1, KEY_SPEC_USER_KEYRING)
    libc.syscall(248, b"user", MARK, b"x", 1, -4)
    os.environ["ARENA_MARK"] = "1"
    attempt(lambda: socket.sethostname("arena-mark"))
    ballast = bytearray(BALLAST_BYTES)
    ballast[::4096] = b"x" * len(ballast[::4096])
    del ballast
    if os.fork() == 0:  # a process that outlives the episode, holding an abstract socket
        os.setsid()
        server = socket.socket(socket.AF_UNIX)
        server.bind("\0arena-mark")
        server.listen(1)
        time.sleep(300)
        os._exit(0)
    time.sleep(0.3)


def lock_tmp():
    """A /tmp nobody may list any more (a scan that cannot read it used to call it clean)."""
    attempt(lambda: os.chmod("/tmp/locked", 0))
    attempt(lambda: os.chmod("/tmp", 0))


class Policy:
    def __init__(self):
        self.acts = 0

    def act(self, obs):
        self.acts += 1
        found = look()
        if self.acts == 1:
            leave_marks()
        else:
            lock_tmp()
        return {agent_id: [float(f) for f in found] for agent_id in obs}
