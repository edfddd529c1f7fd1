"""An evaluation's job i runs its simulator and its agent on CPU i (``pin_jobs``,
evaluator/sandbox/placement.py), and the setting turns that off: shown by what the agent sees
of itself and of its parent, which is the episode's simulator when the agent starts cold under
the process backend (warm, it is the zygote)."""

from __future__ import annotations

import os
import re

import pytest

from arena.config import get_settings
from evaluator.runner import EvaluationRequest, evaluate
from tests.evaluator.runner.conftest import TEST_SANDBOX, write_policy
from tests.evaluator.runner.test_evaluate import few_scenarios
from tests.settings import evaluate_args, with_fields

pytestmark = pytest.mark.slow

# Says where it and its parent may run, then ends the episode at its first step.
REPORTS_CPUS = """
import os, sys


def allowed(pid):
    with open(f"/proc/{pid}/status") as status:
        for line in status:
            if line.startswith("Cpus_allowed_list:"):
                return line.split(":", 1)[1].strip()


class Policy:
    def act(self, obs):
        print(f"cpus agent={allowed('self')} parent={allowed(os.getppid())}", file=sys.stderr)
        raise RuntimeError("seen enough")
"""
SEEN = re.compile(r"cpus agent=(\S+) parent=(\S+)")


def listed(cpus: list[int]) -> str:
    """``cpus`` as the kernel lists them (``0-1,3``)."""
    runs: list[list[int]] = []
    for cpu in sorted(cpus):
        if runs and cpu == runs[-1][-1] + 1:
            runs[-1].append(cpu)
        else:
            runs.append([cpu])
    return ",".join(str(r[0]) if len(r) == 1 else f"{r[0]}-{r[-1]}" for r in runs)


@pytest.mark.parametrize(("pin_jobs", "warm_agents"), [(True, False), (True, True), (False, False)])
def test_each_job_runs_on_its_own_cpu(public_suite, tmp_path, pin_jobs, warm_agents):
    allowed = sorted(os.sched_getaffinity(0))
    if len(allowed) < 2:
        pytest.skip("one CPU here: every job shares it")
    settings = with_fields(
        get_settings(), sandbox={"pin_jobs": pin_jobs, "warm_agents": warm_agents}
    )
    ids = few_scenarios(public_suite, 2)
    source = write_policy(tmp_path / "reports", REPORTS_CPUS)
    out = tmp_path / "out"
    evaluate(
        EvaluationRequest(
            source, public_suite, out_dir=out, scenario_ids=ids, jobs=2, sandbox=TEST_SANDBOX
        ),
        **evaluate_args(settings),
    )
    seen = []
    for scenario_id in ids:
        agent, parent = SEEN.search((out / "logs" / f"{scenario_id}.txt").read_text()).groups()
        assert agent == parent
        seen.append(agent)
    if pin_jobs:
        # Both episodes start at once, as jobs 0 and 1: each on a CPU of its own (CPUs 0 and 1
        # unless another evaluation on this machine holds one, placement.claimed_cpus).
        assert len(set(seen)) == 2
        assert {int(cpu) for cpu in seen} <= set(allowed)
    else:
        assert seen == [listed(allowed)] * 2
