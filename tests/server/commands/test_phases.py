"""`arena admin phases ...` (server/commands/phases.py, phase_options.py). Run against a real
database (both backends), configured like a deployment: through ARENA_* environment variables."""

from __future__ import annotations

from tests.server.builders import make_team, seed_scored


def test_phases_set_episodes_says_the_cost_and_list_shows_it(arena, client):
    output = arena("phases", "set", "final", "--episodes", "3")
    assert "3 episodes per reactive scenario: evaluation takes about 3 times as long" in output
    listing = arena("phases", "list")
    final = next(line for line in listing.splitlines() if line.startswith("final"))
    assert final.split("\t")[6] == "3"
    assert "1 to 64" in arena("phases", "set", "final", "--episodes", "0", ok=False)
    page = client.get("/submit").text
    assert "3 episodes per reactive scenario: evaluation takes about 3 times as long" in page


def test_phases_set_cpu_limits_and_back_to_the_settings(arena, client):
    output = arena(
        "phases", "set", "final", "--step-cpu", "0.5", "--episode-cpu", "60",
        "--evaluation-cpu", "3600",
    )  # fmt: skip
    assert "agent CPU: 0.5 s per act, 60 s per episode, 3600 s per evaluation" in output
    listing = arena("phases", "list")
    final = next(line for line in listing.splitlines() if line.startswith("final"))
    assert final.split("\t")[7] == "0.5 / 60 / 3600"
    assert "must grow" in arena("phases", "set", "final", "--step-cpu", "120", ok=False)
    assert "more than 0" in arena("phases", "set", "final", "--evaluation-cpu", "0", ok=False)
    output = arena("phases", "set", "final", "--default-cpu-limits")
    assert "agent CPU: 1 s per act, 600 s per episode, 64800 s per evaluation" in output


def test_a_phase_on_a_missing_suite_is_refused_and_nothing_saved(arena):
    refused = arena(
        "phases", "create", "warmup", "--suite", "nonexistent", "--open-ended", ok=False
    )  # fmt: skip
    assert "suite 'nonexistent'" in refused and "nothing saved" in refused
    assert "warmup" not in arena("phases", "list")
    assert "1 to 64" in arena("phases", "set", "final", "--episodes", "1000", ok=False)
    assert "end after it starts" in arena(
        "phases", "set", "final", "--starts", "2030-01-02", "--ends", "2030-01-01", ok=False
    )
    assert "unknown scoring profile" in arena("phases", "set", "final", "--profile", "x", ok=False)


def test_a_typo_in_phases_set_creates_nothing_and_names_the_nearest_phase(arena, client):
    """`phases set fianl --suite hidden` once opened a new live phase with no end date."""
    refused = arena("phases", "set", "fianl", "--suite", "hidden", ok=False)
    assert "no phase 'fianl'; did you mean 'final'?" in refused
    assert "arena admin phases create fianl" in refused
    assert "fianl" not in arena("phases", "list") and "fianl" not in client.get("/submit").text
    # Creating is its own command: it says when the phase closes, and never overwrites one.
    assert "--ends T, or --open-ended" in arena(
        "phases", "create", "warmup", "--suite", "public", ok=False
    )
    assert "--suite" in arena("phases", "create", "warmup", "--ends", "2030-01-01", ok=False)
    output = arena("phases", "create", "warmup", "--suite", "public", "--ends", "2099-01-01")
    assert "phase warmup created" in output
    warmup = next(
        line for line in arena("phases", "list").splitlines() if line.startswith("warmup")
    )
    assert warmup.split("\t")[4] == "2099-01-01 00:00" and warmup.split("\t")[-1] == "yes"
    again = arena("phases", "create", "final", "--suite", "public", "--open-ended", ok=False)
    assert "phase 'final' exists" in again and "phases set final" in again


def test_phases_list_shows_a_broken_phase_as_not_open(arena, settings):
    import shutil

    shutil.rmtree(settings.suites.hidden_suite_dir)
    listing = arena("phases", "list")
    final = next(line for line in listing.splitlines() if line.startswith("final"))
    assert final.split("\t")[-1] == "no: broken"
    assert "BROKEN phase 'final': suite 'hidden'" in listing


def test_phases_set_adaptive_says_the_cost_before_and_after_and_list_shows_it(arena, client):
    cost = (
        "adaptive: 2 episode(s) per reactive scenario, then 2 more per round while completion's "
        "95% interval is wider than +/-0.05, up to 20: evaluation takes 2 to 20 times as long"
    )
    args = ("phases", "set", "final", "--episodes", "2", "--adaptive-target", "0.05")
    preview = arena(*args, "--max-episodes", "20", "--dry-run")
    assert cost in " ".join(preview.split()) and "unchanged (dry run)" in preview
    assert "adaptive" not in arena("phases", "list")
    assert cost in " ".join(arena(*args, "--max-episodes", "20").split())
    assert f"final (+): {cost}" in " ".join(arena("phases", "list").split())
    assert cost.replace("'", "&#39;") in " ".join(client.get("/submit").text.split())
    assert "both" in arena(*args, ok=False)
    arena("phases", "set", "final", "--fixed-episodes")
    assert "adaptive" not in arena("phases", "list")


def test_phases_release_waits_for_the_close_and_list_says_it(arena):
    refused = arena("phases", "release", "final", ok=False)
    assert "has no end date" in refused and "Traceback" not in refused
    arena("phases", "set", "final", "--ends", "2020-01-01T00:00")
    done = " ".join(arena("phases", "release", "final").split())
    assert "released" in done and "/api/v1/scenarios/released/final.zip" in done
    assert "released (suite downloadable, episodes visible): final" in arena("phases", "list")


def test_delete_a_phase_says_what_goes_and_spares_the_default_one(arena, db):
    other, _ = make_team(db, "beta")
    seed_scored(db, other, (0.5, 400.0, 0.1, 0.0), phase="validation")
    refused = arena("phases", "delete", "final", "--yes", ok=False)
    assert "cannot be deleted" in refused
    assert "phase validation: 1 submission(s)" in arena("phases", "delete", "validation", "--yes")
    assert "validation" not in arena("phases", "list")
