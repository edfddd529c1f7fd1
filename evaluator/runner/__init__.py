"""The evaluation core: one submission through a scenario suite, scenario by scenario.

``run_scenario`` is the unit of work (the service's workers call it too) and ``score_outcomes``
turns outcomes into a :class:`evaluator.summary.Summary` (the service stores what it returns);
``evaluate`` runs a whole suite locally with resume.
"""

from evaluator.runner.evaluate import EvaluationRequest, Progress, ResultsDirError, evaluate
from evaluator.runner.results import score_outcome, score_outcomes, score_results_dir
from evaluator.runner.scenario import (
    SandboxedAgentFactory,
    ScenarioOutcome,
    new_run_key,
    run_scenario,
    sandbox_labels,
)

__all__ = [
    "EvaluationRequest",
    "Progress",
    "ResultsDirError",
    "SandboxedAgentFactory",
    "ScenarioOutcome",
    "evaluate",
    "new_run_key",
    "run_scenario",
    "sandbox_labels",
    "score_outcome",
    "score_outcomes",
    "score_results_dir",
]
