"""Episodes to watch: the replay of a submission's scenario, and the expert's drive through each
public scenario.

Who sees what follows the phase rules of the logs and downloads: a team watches its own episodes in
a phase of full visibility (validation) and none in a hidden phase; organisers watch every
episode; the public scenarios' expert drives are open to anyone.
"""

from __future__ import annotations

import hashlib
import json
import tempfile
import threading
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

from sqlalchemy.orm import Session

from arena.config import SuiteSettings
from arena.errors import RecordError
from arena.suite import public_suite_dir
from evaluator.viewer.model import load_replay
from scenarios.verify import verify_scenario
from server.core.artifacts import ArtifactStore, MissingArtifact
from server.models import Submission
from server.services import scenarios
from server.services.errors import NotFound
from server.services.phases import check_team_may_see_output, get_phase
from server.services.submissions import current_run

# The expert runs one simulation (a child process) at a time, whatever the number of requests.
_expert_lock = threading.Lock()


def submission_replay(
    session: Session,
    store: ArtifactStore,
    submission: Submission,
    scenario_id: str,
    *,
    organiser: bool = False,
) -> dict:
    """The replay of ``scenario_id`` in the run whose score stands (403 for a team in a hidden
    phase, 404 when the scenario has no stored episode)."""
    if not organiser:
        check_team_may_see_output(get_phase(session, submission.phase))
    run = current_run(submission)
    result = next((r for r in run.results if r.scenario_id == scenario_id), None) if run else None
    if result is None or not result.record_key:
        raise NotFound(
            f"submission {submission.id} has no recorded episode of {scenario_id!r} "
            "(not run yet, or the agent never drove a step)"
        )
    with tempfile.TemporaryDirectory(prefix="arena-replay-") as scratch:
        try:
            record = store.fetch(result.record_key, Path(scratch) / "record.npz")
        except MissingArtifact:
            raise NotFound(f"the episode record of {scenario_id!r} is no longer stored") from None
        return _replay_json(record, Path(run.suite_dir))


@dataclass(frozen=True)
class ReplayDocument:
    """A replay's JSON, encoded once, and its entity tag."""

    body: bytes
    etag: str


# The public replays' JSON, per content key: anyone may ask for them, and rebuilding one from its
# record took ~66 ms of the API per anonymous request. Bounded: the public suite is small.
_public_documents: OrderedDict[str, ReplayDocument] = OrderedDict()
_PUBLIC_DOCUMENTS_KEPT = 64


def public_replay(suites: SuiteSettings, store: ArtifactStore, scenario_id: str) -> ReplayDocument:
    """The expert's drive through a public scenario: simulated on the first request, then kept in
    the artifact store under the scenario's content hash, and its JSON in this process."""
    entry = next((e for e in scenarios.public_scenarios(suites) if e.id == scenario_id), None)
    if entry is None:
        raise NotFound(f"no public scenario {scenario_id!r}")
    key = f"replays/public/{entry.hash or 'unhashed'}/{scenario_id}.npz"
    with _expert_lock:
        cached = _public_documents.get(key)
        if cached is not None:
            _public_documents.move_to_end(key)
            return cached
    suite_dir = public_suite_dir(suites)
    with tempfile.TemporaryDirectory(prefix="arena-replay-") as scratch:
        record = Path(scratch) / f"{scenario_id}.npz"
        with _expert_lock:
            if store.exists(key):
                store.fetch(key, record)
            else:
                verify_scenario(suite_dir / scenario_id, Path(scratch))
                if not record.exists():
                    raise NotFound(f"the expert could not drive {scenario_id!r}")
                store.put(key, record)
        body = json.dumps(_replay_json(record, suite_dir), separators=(",", ":")).encode()
    document = ReplayDocument(body, '"' + hashlib.sha256(body).hexdigest()[:32] + '"')
    with _expert_lock:
        _public_documents[key] = document
        while len(_public_documents) > _PUBLIC_DOCUMENTS_KEPT:
            _public_documents.popitem(last=False)
    return document


def _replay_json(record: Path, suite_dir: Path) -> dict:
    try:
        return load_replay(record, suite_dir).to_json()
    except RecordError as exc:
        raise NotFound(f"no replay: {exc}") from exc
