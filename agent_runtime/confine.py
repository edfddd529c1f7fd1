"""What confines an agent inside its sandbox, the same under every isolating backend: the system
calls it may make (a seccomp filter) and, for each episode of a warm sandbox, state made new.

Standard library only, no import of this project: it runs in the sandbox next to ``main.py``, and
the evaluator imports it too, to hand the very same filter to the backends (bubblewrap's
``--seccomp``, Docker's ``seccomp=`` profile).

**The filter** is one table, :data:`DENIED`: keyrings, kernel modules, BPF, ptrace, mounting,
new namespaces (``unshare``, ``setns``, ``clone`` with a namespace flag, ``clone3``), io_uring,
clock and host settings... are refused with ``EPERM`` (``clone3`` with ``ENOSYS``, so the C
library falls back to ``clone``, whose flags a filter can read). Another architecture than the
host's (the x32 ABI included) is killed. :func:`program` renders it as classic BPF,
:func:`docker_profile` as Docker's JSON profile.

**Fresh episodes** (:func:`fresh_episode`): the warm parent's child, before any participant code,
enters a user namespace of its own (same uid, mapped to itself) and, in it, new mount, IPC, network
and UTS namespaces; mounts new tmpfs on ``/tmp`` and ``/dev/shm``, a new ``mqueue`` on
``/dev/mqueue`` and an empty read-only tmpfs over ``/sys/fs/cgroup``; drops every capability and
installs the filter. Everything it can write then vanishes with its last process: the next episode
starts from nothing that was cleaned, only from what was made new.
"""

from __future__ import annotations

import ctypes
import errno
import json
import os
import platform
import struct

# <linux/audit.h>
AUDIT_ARCH = {"x86_64": 0xC000003E}
X32_SYSCALL_BIT = 0x40000000
# x86_64 numbers (<asm/unistd_64.h>) of the calls no agent may make.
SYSCALLS_X86_64 = {
    "_sysctl": 156,
    "acct": 163,
    "add_key": 248,
    "adjtimex": 159,
    "afs_syscall": 183,
    "bpf": 321,
    "chroot": 161,
    "clock_adjtime": 305,
    "clock_settime": 227,
    "create_module": 174,
    "delete_module": 176,
    "fanotify_init": 300,
    "finit_module": 313,
    "fsconfig": 431,
    "fsmount": 432,
    "fsopen": 430,
    "fspick": 433,
    "get_kernel_syms": 177,
    "getpmsg": 181,
    "init_module": 175,
    "io_uring_enter": 426,
    "io_uring_register": 427,
    "io_uring_setup": 425,
    "ioperm": 173,
    "iopl": 172,
    "kcmp": 312,
    "kexec_file_load": 320,
    "kexec_load": 246,
    "keyctl": 250,
    "lookup_dcookie": 212,
    "migrate_pages": 256,
    "mount": 165,
    "mount_setattr": 442,
    "move_mount": 429,
    "move_pages": 279,
    "name_to_handle_at": 303,
    "nfsservctl": 180,
    "open_by_handle_at": 304,
    "open_tree": 428,
    "perf_event_open": 298,
    "pivot_root": 155,
    "process_vm_readv": 310,
    "process_vm_writev": 311,
    "ptrace": 101,
    "putpmsg": 182,
    "query_module": 178,
    "quotactl": 179,
    "reboot": 169,
    "request_key": 249,
    "security": 185,
    "setdomainname": 171,
    "sethostname": 170,
    "setns": 308,
    "settimeofday": 164,
    "swapoff": 168,
    "swapon": 167,
    "syslog": 103,
    "tuxcall": 184,
    "umount2": 166,
    "unshare": 272,
    "uselib": 134,
    "userfaultfd": 323,
    "ustat": 136,
    "vhangup": 153,
    "vserver": 236,
}
CLONE_X86_64 = 56
CLONE3_X86_64 = 435
DENIED = tuple(sorted(SYSCALLS_X86_64))
# What the warm parent's child needs to make its episode new (fresh_episode) before it installs
# the full filter: the sandbox's own filter lets the warm parent, and only it, make these calls.
WARM_PARENT_NEEDS = ("mount", "unshare")

CLONE_NEWNS = 0x00020000
CLONE_NEWCGROUP = 0x02000000
CLONE_NEWUTS = 0x04000000
CLONE_NEWIPC = 0x08000000
CLONE_NEWUSER = 0x10000000
CLONE_NEWPID = 0x20000000
CLONE_NEWNET = 0x40000000
NAMESPACE_FLAGS = (
    CLONE_NEWNS,
    CLONE_NEWCGROUP,
    CLONE_NEWUTS,
    CLONE_NEWIPC,
    CLONE_NEWUSER,
    CLONE_NEWPID,
    CLONE_NEWNET,
)

# <linux/filter.h>, <linux/seccomp.h>
BPF_LD_W_ABS = 0x20
BPF_JEQ_K = 0x15
BPF_JGE_K = 0x35
BPF_JSET_K = 0x45
BPF_RET_K = 0x06
SECCOMP_RET_KILL_PROCESS = 0x80000000
SECCOMP_RET_ERRNO = 0x00050000
SECCOMP_RET_ALLOW = 0x7FFF0000
OFFSET_NR, OFFSET_ARCH, OFFSET_ARG0 = 0, 4, 16
PR_SET_NO_NEW_PRIVS = 38
PR_SET_SECCOMP = 22
SECCOMP_MODE_FILTER = 2
PR_CAPBSET_DROP = 24
LINUX_CAPABILITY_VERSION_3 = 0x20080522
LAST_CAPABILITY = 63

MS_NOSUID, MS_NODEV, MS_NOEXEC, MS_RDONLY = 0x2, 0x4, 0x8, 0x1
MS_REC, MS_PRIVATE = 0x4000, 0x40000


class ConfinementError(OSError):
    """The sandbox cannot be confined as the contract says (raised before any agent code)."""


def supported() -> str | None:
    """Why this machine's architecture has no filter, or None when it has one."""
    machine = platform.machine()
    return None if machine in AUDIT_ARCH else f"no seccomp table for {machine}"


def denied(warm_parent: bool) -> tuple[str, ...]:
    """The calls refused to the sandbox (``warm_parent``: the outer filter of a warm sandbox,
    which lets its parent make each episode new) or to an agent."""
    return tuple(n for n in DENIED if not (warm_parent and n in WARM_PARENT_NEEDS))


def program(warm_parent: bool = False) -> bytes:
    """The filter as ``struct sock_filter`` array bytes (what ``bwrap --seccomp`` reads)."""
    deny = SECCOMP_RET_ERRNO | errno.EPERM
    numbers = [SYSCALLS_X86_64[name] for name in denied(warm_parent)]
    # Layout: arch check, x32 check, one jeq per denied call (to DENY), clone3, clone, ALLOW,
    # clone's flag tests, DENY, KILL.
    code: list[tuple[int, int, int, int]] = []
    # Where the shared endings are: 4 checks of arch and number, the denied calls, clone3, clone.
    allow = 4 + len(numbers) + 2
    flags_start = allow + 1
    deny_at = flags_start + 1 + len(NAMESPACE_FLAGS) + 1
    enosys_at = deny_at + 1
    kill_at = enosys_at + 1

    def jump(at: int, target: int) -> int:
        offset = target - at - 1
        assert 0 <= offset < 256, "filter too long for one jump"
        return offset

    code.append((BPF_LD_W_ABS, 0, 0, OFFSET_ARCH))
    code.append((BPF_JEQ_K, 0, jump(1, kill_at), AUDIT_ARCH[platform.machine()]))
    code.append((BPF_LD_W_ABS, 0, 0, OFFSET_NR))
    code.append((BPF_JGE_K, jump(3, kill_at), 0, X32_SYSCALL_BIT))
    for number in numbers:
        at = len(code)
        code.append((BPF_JEQ_K, jump(at, deny_at), 0, number))
    at = len(code)
    code.append((BPF_JEQ_K, jump(at, enosys_at), 0, CLONE3_X86_64))
    at = len(code)
    code.append((BPF_JEQ_K, jump(at, flags_start), 0, CLONE_X86_64))
    assert len(code) == allow
    code.append((BPF_RET_K, 0, 0, SECCOMP_RET_ALLOW))
    # clone: its flags are the low 32 bits of the first argument (little-endian).
    code.append((BPF_LD_W_ABS, 0, 0, OFFSET_ARG0))
    for flag in NAMESPACE_FLAGS:
        at = len(code)
        code.append((BPF_JSET_K, jump(at, deny_at), 0, flag))
    code.append((BPF_RET_K, 0, 0, SECCOMP_RET_ALLOW))
    assert len(code) == deny_at
    code.append((BPF_RET_K, 0, 0, deny))
    code.append((BPF_RET_K, 0, 0, SECCOMP_RET_ERRNO | errno.ENOSYS))
    code.append((BPF_RET_K, 0, 0, SECCOMP_RET_KILL_PROCESS))
    return b"".join(struct.pack("=HBBI", *instruction) for instruction in code)


def docker_profile(warm_parent: bool = False) -> str:
    """The same filter as Docker's JSON seccomp profile."""
    eperm = {"action": "SCMP_ACT_ERRNO", "errnoRet": errno.EPERM}
    rules = [
        {"names": list(denied(warm_parent)), **eperm},
        {"names": ["clone3"], "action": "SCMP_ACT_ERRNO", "errnoRet": errno.ENOSYS},
    ]
    for flag in NAMESPACE_FLAGS:
        masked = {"index": 0, "value": flag, "valueTwo": flag, "op": "SCMP_CMP_MASKED_EQ"}
        rules.append({"names": ["clone"], "args": [masked], **eperm})
    profile = {
        "defaultAction": "SCMP_ACT_ALLOW",
        "architectures": ["SCMP_ARCH_X86_64"],
        "syscalls": rules,
    }
    return json.dumps(profile)


class _SockFprog(ctypes.Structure):
    _fields_ = [("len", ctypes.c_ushort), ("filter", ctypes.c_void_p)]


def _libc() -> ctypes.CDLL:
    return ctypes.CDLL(None, use_errno=True)


def _check(result: int, what: str) -> None:
    if result != 0:
        number = ctypes.get_errno()
        raise ConfinementError(number, f"{what}: {os.strerror(number)}")


def install_filter(warm_parent: bool = False) -> None:
    """Install the filter on this process (and everything it starts); irreversible."""
    reason = supported()
    if reason:
        raise ConfinementError(errno.ENOSYS, reason)
    libc = _libc()
    code = program(warm_parent)
    buffer = ctypes.create_string_buffer(code, len(code))
    fprog = _SockFprog(len(code) // 8, ctypes.cast(buffer, ctypes.c_void_p))
    _check(libc.prctl(PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0), "no_new_privs")
    _check(libc.prctl(PR_SET_SECCOMP, SECCOMP_MODE_FILTER, ctypes.byref(fprog), 0, 0), "seccomp")


def drop_capabilities() -> None:
    """Give up every capability (those a new user namespace grants its first process)."""
    libc = _libc()
    for capability in range(LAST_CAPABILITY + 1):
        if libc.prctl(PR_CAPBSET_DROP, capability, 0, 0, 0) != 0:
            break  # past the kernel's last capability
    header = struct.pack("=Ii", LINUX_CAPABILITY_VERSION_3, 0)
    data = bytes(24)  # two zeroed __user_cap_data_struct: effective, permitted, inheritable
    _check(libc.capset(header, data), "capset")


def _write(path: str, text: str) -> None:
    with open(path, "w") as file:
        file.write(text)


def _mount(libc, source: bytes, target: str, kind: bytes, flags: int, options: str) -> None:
    _check(
        libc.mount(source, target.encode(), kind, flags, options.encode() or None),
        f"mount {kind.decode()} on {target}",
    )


def fresh_episode(scratch_bytes: int) -> None:
    """Make this process's writable state new (see the module's docstring), then confine it.
    ``scratch_bytes``: the size of its new ``/tmp`` and of its new ``/dev/shm``."""
    libc = _libc()
    uid, gid = os.getuid(), os.getgid()
    flags = CLONE_NEWUSER | CLONE_NEWNS | CLONE_NEWIPC | CLONE_NEWNET | CLONE_NEWUTS
    _check(libc.unshare(flags), "unshare")
    _write("/proc/self/setgroups", "deny")
    _write("/proc/self/uid_map", f"{uid} {uid} 1")
    _write("/proc/self/gid_map", f"{gid} {gid} 1")
    _check(libc.mount(None, b"/", None, MS_REC | MS_PRIVATE, None), "make / private")
    hardened = MS_NOSUID | MS_NODEV
    inodes = max(scratch_bytes // 4096, 1024)
    scratch = f"size={scratch_bytes},nr_inodes={inodes},mode=1777"
    _mount(libc, b"tmpfs", "/tmp", b"tmpfs", hardened, scratch)
    if os.path.isdir("/dev/shm"):
        _mount(libc, b"tmpfs", "/dev/shm", b"tmpfs", hardened | MS_NOEXEC, scratch)
    if os.path.isdir("/dev/mqueue"):
        _mount(libc, b"mqueue", "/dev/mqueue", b"mqueue", hardened | MS_NOEXEC, "")
    if os.path.isdir("/sys/fs/cgroup"):
        empty = "size=4096,nr_inodes=1,mode=555"
        _mount(libc, b"tmpfs", "/sys/fs/cgroup", b"tmpfs", hardened | MS_NOEXEC | MS_RDONLY, empty)
    drop_capabilities()
    install_filter()
