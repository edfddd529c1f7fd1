"""The agents' seccomp filter and fresh-episode namespaces, in a real child process of this
machine's kernel (the sandbox tests check them again from inside Docker and bubblewrap)."""

from __future__ import annotations

import ctypes
import errno
import json
import os

import pytest

from agent_runtime import confine

pytestmark = pytest.mark.skipif(confine.supported() is not None, reason="no table for this arch")


def in_child(body) -> dict:
    """Run ``body()`` in a forked child; its JSON-able answer."""
    reader, writer = os.pipe()
    pid = os.fork()
    if pid == 0:
        os.close(reader)
        try:
            answer = body()
        except BaseException as error:  # reported, never raised past the fork
            answer = {"error": repr(error)}
        os.write(writer, json.dumps(answer).encode())
        os._exit(0)
    os.close(writer)
    data = b""
    while chunk := os.read(reader, 65536):
        data += chunk
    os.close(reader)
    os.waitpid(pid, 0)
    return json.loads(data)


def errno_of(result: int) -> int:
    return ctypes.get_errno() if result == -1 else 0


def filtered(warm_parent: bool):
    def body() -> dict:
        libc = ctypes.CDLL(None, use_errno=True)
        confine.install_filter(warm_parent=warm_parent)
        forked = os.fork()  # plain clone: allowed
        if forked == 0:
            os._exit(7)
        _, status = os.waitpid(forked, 0)
        return {
            "fork": os.waitstatus_to_exitcode(status),
            "keyctl": errno_of(libc.syscall(250, 0, -3, 0)),
            "add_key": errno_of(libc.syscall(248, b"user", b"k", b"x", 1, -4)),
            "clone_newuser": errno_of(libc.syscall(56, confine.CLONE_NEWUSER | 17, 0, 0, 0, 0)),
            "clone3": errno_of(libc.syscall(435, 0, 0)),
            "ptrace": errno_of(libc.ptrace(0, 0, None, None)),
            "unshare": errno_of(libc.unshare(0)),
            "getpid": os.getpid() > 0,
        }

    return body


def test_the_agents_filter_refuses_the_table_and_allows_the_rest():
    answer = in_child(filtered(warm_parent=False))
    assert answer == {
        "fork": 7,
        "keyctl": errno.EPERM,
        "add_key": errno.EPERM,
        "clone_newuser": errno.EPERM,
        "clone3": errno.ENOSYS,
        "ptrace": errno.EPERM,
        "unshare": errno.EPERM,
        "getpid": True,
    }


def test_a_warm_parents_filter_lets_it_unshare_and_nothing_else_more():
    answer = in_child(filtered(warm_parent=True))
    assert answer["unshare"] == 0 and answer["keyctl"] == errno.EPERM
    assert answer["clone_newuser"] == errno.EPERM  # only unshare, from the parent's child


def test_the_docker_profile_is_the_same_table():
    profile = json.loads(confine.docker_profile())
    denied = profile["syscalls"][0]["names"]
    assert denied == list(confine.DENIED) and profile["defaultAction"] == "SCMP_ACT_ALLOW"
    warm = json.loads(confine.docker_profile(warm_parent=True))["syscalls"][0]["names"]
    assert set(denied) - set(warm) == set(confine.WARM_PARENT_NEEDS)


@pytest.mark.skipif(os.geteuid() != 0, reason="drops to uid 65534 first, as in a sandbox")
def test_a_fresh_episode_writes_nowhere_its_parent_sees():
    def body() -> dict:
        libc = ctypes.CDLL(None, use_errno=True)
        os.setgid(65534)
        os.setuid(65534)
        libc.prctl(4, 1, 0, 0, 0)  # dumpable again after setuid, as the zygote's child is
        confine.fresh_episode(1 << 20)
        with open("/tmp/arena-confine-mark", "w") as mark:
            mark.write("x")
        return {
            "sees": os.path.exists("/tmp/arena-confine-mark"),
            "uid": os.getuid(),
            "caps": open("/proc/self/status").read().split("CapEff:")[1].split()[0],
        }

    answer = in_child(body)
    assert answer == {"sees": True, "uid": 65534, "caps": "0000000000000000"}
    assert not os.path.exists("/tmp/arena-confine-mark")
