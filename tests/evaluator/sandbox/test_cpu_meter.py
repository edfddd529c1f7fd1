from __future__ import annotations

import os
import subprocess
import sys

from arena.config import SandboxKind
from evaluator.sandbox import cgroup
from evaluator.sandbox.cpu import CpuMeter
from tests.evaluator.sandbox.conftest import usable


def test_a_reader_keeps_the_cgroup_file_open_and_reads_its_current_value(tmp_path):
    v1 = tmp_path / "cpuacct.usage"
    v1.write_text("1500000000\n")
    v2 = tmp_path / "cpu.stat"
    v2.write_text("usage_usec 2500000\nuser_usec 2000000\nsystem_usec 500000\n")
    readers = [CpuMeter(cgroup_file=str(v1)).open(), CpuMeter(cgroup_file=str(v2)).open()]
    assert [r.seconds() for r in readers] == [1.5, 2.5]
    # Rewritten in place, as the kernel's counters are: the open file shows the new value.
    with open(v1, "r+") as f:
        f.write("3000000000\n")
    with open(v2, "r+") as f:
        f.write("usage_usec 4000000\n")
    assert [r.seconds() for r in readers] == [3.0, 4.0]
    for reader in readers:
        reader.close()
        reader.close()  # closing twice is harmless


def test_a_reader_of_a_missing_file_or_a_process_tree_answers_as_the_meter(tmp_path):
    missing = CpuMeter(cgroup_file=str(tmp_path / "gone" / "cpu.stat"))
    assert missing.open().seconds() is None
    tree = CpuMeter(root_pid=os.getpid())
    reader = tree.open()
    assert reader.seconds() is not None and abs(reader.seconds() - tree.seconds()) < 1.0
    reader.close()


BURN = """
import sys, time
for line in sys.stdin:
    start = time.process_time()
    while time.process_time() - start < 0.002:
        pass
    print("burnt", flush=True)
"""


def burst_readings(meter_of, **popen) -> list[float]:
    """What ``meter_of(child)``'s reader reads for each of a child's 2 ms CPU bursts."""
    child = subprocess.Popen(
        [sys.executable, "-c", BURN],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        **popen,
    )
    try:
        reader = meter_of(child).open()
        used = []
        for _ in range(6):
            before = reader.seconds()
            child.stdin.write("go\n")
            child.stdin.flush()
            assert child.stdout.readline() == "burnt\n"
            used.append(reader.seconds() - before)
        reader.close()
        return used[1:]  # the first burst also counts the interpreter's start
    finally:
        child.kill()
        child.wait()


def test_a_process_tree_is_read_finer_than_clock_ticks():
    # Clock ticks (10 ms) would read each 2 ms burst as 0 or 10 ms: a cheap agent's episode
    # would show no CPU at all.
    used = burst_readings(lambda child: CpuMeter(root_pid=child.pid))
    assert all(0.002 <= seconds < 0.009 for seconds in used), used


def test_a_sandbox_group_counts_the_cpu_of_its_processes_in_one_counter(settings):
    """Bubblewrap's meter is its group's counter (one read an act), as fine as the tree's walk
    (hundreds of microseconds an act)."""
    usable(SandboxKind.bubblewrap, settings)  # bubblewrap runs only where a group can be made
    found = cgroup.hierarchy()
    assert isinstance(found, cgroup.Hierarchy), found
    group = cgroup.SandboxGroup.create(found, f"{cgroup.GROUP_PREFIX}meter-{os.getpid()}", None)
    try:
        usage = group.cpu_usage_file
        assert usage is not None, found
        used = burst_readings(lambda _: CpuMeter(cgroup_file=str(usage)), preexec_fn=group.join)
        assert all(0.002 <= seconds < 0.009 for seconds in used), used
    finally:
        group.remove()
