"""The evaluation runner: one submission through a scenario set, scenario by scenario.

``run_scenario`` is the unit of work (the service's tasks call it too); ``evaluate`` runs a whole
set locally with resume; ``summarize`` and ``score_results_dir`` turn outcomes and stored records
into a :class:`evaluator.summary.Summary`.
"""

from evaluator.runner.evaluate import Progress, ResultsDirError, evaluate
from evaluator.runner.manifest import Manifest, SuiteError, load_manifest, resolve_suite
from evaluator.runner.results import score_results_dir, summarize
from evaluator.runner.scenario import (
    SandboxedAgentFactory,
    ScenarioOutcome,
    new_run_key,
    run_scenario,
    sandbox_labels,
)

__all__ = [
    "Manifest",
    "Progress",
    "ResultsDirError",
    "SandboxedAgentFactory",
    "ScenarioOutcome",
    "SuiteError",
    "evaluate",
    "load_manifest",
    "new_run_key",
    "resolve_suite",
    "run_scenario",
    "sandbox_labels",
    "score_results_dir",
    "summarize",
]
