"""`arena up`: the whole service on one machine with the embedded defaults (SQLite database,
SQLAlchemy broker), API and worker as child processes it owns.

The children die with it whatever ends it (Ctrl-C, SIGTERM, even SIGKILL: the kernel sends them
SIGTERM when their parent dies), one instance serves a data folder and a port at a time, and the
demo team's token stays the same across restarts.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import fcntl
import os
import secrets
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
from rich.console import Console
from rich.panel import Panel
from sqlalchemy import make_url

from arena.child_env import SERVICE_VARIABLES, child_environment
from arena.config import (
    SandboxSettings,
    ServiceSettings,
    Settings,
    SettingsGroup,
    StorageSettings,
    SuiteSettings,
    get_settings,
)
from arena.errors import ArenaError
from arena.suite import hidden_suite_dir, load_suite, public_suite_dir
from evaluator import sandbox
from evaluator.sandbox.backend import owner_labels
from scenarios.ids import seed_fingerprint
from server.core.db import Database
from server.core.migrate import upgrade_database
from server.core.permissions import close_service_folders
from server.services import teams
from server.services.errors import NotFound

ARENA = [sys.executable, "-c", "from arena_command import app; app()"]
# How long the worker and the API get to stop after SIGTERM before they are killed [s]. The
# worker hands its running jobs back at once (a job it could not is reaped when its lease ends).
STOP_GRACE_S = 15.0


class AlreadyServed(ArenaError, RuntimeError):
    """Another instance serves this data folder, or something else listens on the port."""


def run_embedded(console: Console, *, host: str, port: int, demo_team: str) -> None:
    settings = get_settings()
    data = settings.storage.resolved_data_dir
    data.mkdir(parents=True, exist_ok=True)
    lock = _lock_data_folder(data)  # held until this process ends, however it ends
    _check_port_free(host, port)
    admin_token = settings.service.admin_token or _stored_admin_token(data)
    env = service_environment(settings, data, secrets_folder(data))

    shown = make_url(settings.storage.resolved_database_url).render_as_string(hide_password=True)
    console.print(f"database: {shown}")
    upgrade_database(settings.storage.resolved_database_url)

    env["ARENA_PUBLIC_SUITE_DIR"] = str(_public_suite(console, settings.suites, data, env))
    hidden = _hidden_suite(console, settings.suites, data, env)
    env["ARENA_HIDDEN_SUITE_DIR"] = str(hidden)
    for warning in close_service_folders(data, hidden):
        console.print(f"[red]{warning}[/red]")

    kind = sandbox.check_service_kind(None, settings.sandbox)
    env["ARENA_SANDBOX"] = kind.value
    console.print(f"sandbox: [bold]{kind.value}[/bold]")

    token = _demo_team_token(settings.storage, demo_team)

    children = [
        _start_child([*ARENA, "worker"], env),
        _start_child([*ARENA, "serve", "--host", host, "--port", str(port)], env),
    ]
    url = f"http://{host}:{port}"
    signal.signal(signal.SIGTERM, _interrupt)  # `kill` stops it as cleanly as Ctrl-C
    # Ctrl-C too, even when started from a background job of a script, which inherits SIGINT
    # ignored (as POSIX shells start them) and would never stop on it.
    signal.signal(signal.SIGINT, _interrupt)
    try:
        _wait_healthy(f"{url}/api/v1/healthz", children)
        console.print(
            Panel.fit(
                f"Driving Arena is up at [bold]{url}[/bold]\n\n"
                f"team [bold]{demo_team}[/bold] token: [green]{token}[/green]\n"
                f"admin token: [yellow]{admin_token}[/yellow]\n\n"
                f"Submit at {url}/submit · API docs at {url}/docs · Ctrl-C stops everything",
                title="arena up",
            )
        )
        while all(child.poll() is None for child in children):
            time.sleep(0.5)
        console.print("[red]a service process exited; stopping the others[/red]")
    except KeyboardInterrupt:
        console.print("stopping…")
    finally:
        _stop(console, children)
        _remove_leftover_sandboxes(console, settings.sandbox, data)
        lock.close()


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


_PR_SET_PDEATHSIG = 1


def _die_with_parent() -> None:
    """In the child, before exec: the kernel sends it SIGTERM when `arena up` dies."""
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)


def _start_child(command: list[str], env: dict) -> subprocess.Popen:
    # A session of its own, so stopping it reaches its children (simulators, agents) too.
    return subprocess.Popen(command, env=env, start_new_session=True, preexec_fn=_die_with_parent)


def _lock_data_folder(data: Path):
    """An exclusive lock on the data folder for as long as this process lives."""
    handle = (data / "arena-up.lock").open("a+")
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        handle.seek(0)
        owner = handle.read().strip() or "another process"
        handle.close()
        raise AlreadyServed(
            f"{data} is already served by `arena up` ({owner}); stop it first, or use another "
            "ARENA_DATA_DIR"
        ) from None
    handle.truncate(0)
    handle.write(f"pid {os.getpid()}\n")
    handle.flush()
    return handle


def _check_port_free(host: str, port: int) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        # As the server binds: connections of a stopped instance lingering in TIME_WAIT do not
        # count, only a socket that listens there.
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((host, port))
        except OSError as exc:
            if exc.errno != errno.EADDRINUSE:
                raise
            raise AlreadyServed(
                f"port {port} on {host} is already in use (another `arena up`?); stop it or "
                "pass --port"
            ) from None


def _remove_leftover_sandboxes(console: Console, config: SandboxSettings, data_dir: Path) -> None:
    """Agents of episodes the stopped worker left behind (it was this data folder's only
    worker); other services' and local evaluations' sandboxes on this host are not ours."""
    try:
        owner = owner_labels(data_dir)
        removed = sandbox.cleanup(config, owner)
    except ArenaError as exc:
        console.print(f"[yellow]could not look for leftover sandboxes: {exc}[/yellow]")
        return
    if removed:
        console.print(f"removed {removed} leftover sandbox(es)")


def _admin_token_path(data: Path) -> Path:
    return data / "admin_token"


def _stored_admin_token(data: Path) -> str:
    """The admin token of this data folder, made once and kept readable only by its owner."""
    path = _admin_token_path(data)
    if not path.exists():
        path.write_text(secrets.token_urlsafe(32) + "\n")
        path.chmod(0o600)
    return path.read_text().strip()


def secrets_folder(data: Path) -> Path:
    """Where the secrets given as plain variables are handed to the children, owner-only."""
    folder = data / "secrets"
    folder.mkdir(mode=0o700, exist_ok=True)
    folder.chmod(0o700)
    return folder


def service_environment(settings: Settings, data: Path, secrets_dir: Path) -> dict[str, str]:
    """The API's and the worker's environment: the settings' variables but the secrets, which
    they read from files (never from their environment, which their own children would
    inherit); the hidden seed is the suite builder's alone."""
    env = child_environment({"ARENA_DATA_DIR": str(data)}, inherit=SERVICE_VARIABLES)
    env.pop(SuiteSettings.env_names()["hidden_seed_file"], None)
    env |= _secret_files(secrets_dir, settings.storage, settings.service)
    if settings.service.admin_token is None:
        env[ServiceSettings.env_names()["admin_token_file"]] = str(_admin_token_path(data))
    return env


def _secret_files(folder: Path, *groups: SettingsGroup) -> dict[str, str]:
    """The ``*_FILE`` variable of each secret of ``groups`` that was given as a plain variable,
    naming a file in ``folder`` (owner-only) that holds it; those given as files are inherited
    as they are."""
    env = {}
    for group in groups:
        names = type(group).env_names()
        for field in type(group).secret_fields:
            value = getattr(group, field)
            if value in (None, "") or getattr(group, f"{field}_file") is not None:
                continue
            path = folder / field
            path.unlink(missing_ok=True)
            descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o400)
            with os.fdopen(descriptor, "w") as handle:
                handle.write(f"{value}\n")
            env[names[f"{field}_file"]] = str(path)
    return env


def _build_suite(console: Console, env: dict, suite: str, out: Path, *options: str) -> None:
    command = [*ARENA, "scenarios", "build", "--suite", suite, "--out", str(out), *options]
    console.print(f"building the {suite} scenario suite in {out} …")
    subprocess.run(command, env=env, check=True)


def _public_suite(console: Console, suites: SuiteSettings, data_dir: Path, env: dict) -> Path:
    folder = public_suite_dir(suites)
    if not (folder / "manifest.json").exists():
        folder = data_dir / "suites" / "public"
        if not (folder / "manifest.json").exists():
            _build_suite(console, env, "public", folder)
    console.print(f"public suite: {folder}")
    return folder


def _hidden_suite(console: Console, suites: SuiteSettings, data_dir: Path, env: dict) -> Path:
    folder = hidden_suite_dir(suites, data_dir)
    if (folder / "manifest.json").exists():
        console.print(f"hidden suite: {folder}")
        # Said at every start, not only the first: a demo folder must not drift into a
        # competition unnoticed.
        built_from = load_suite(folder).manifest.seed_fingerprint
        if built_from == seed_fingerprint(suites.development_seed):
            _warn_development_seed(console, suites.development_seed)
        return folder
    if suites.hidden_seed is None:
        _warn_development_seed(console, suites.development_seed)
        _build_suite(console, env, "hidden", folder, "--dev")
    else:
        # From a file, never the command line (which `ps` shows to every user).
        seed_file = _secret_files(secrets_folder(data_dir), suites)
        _build_suite(console, env | seed_file, "hidden", folder)
    return folder


def _warn_development_seed(console: Console, seed: int) -> None:
    console.print(
        Panel.fit(
            "No secret seed is configured (ARENA_HIDDEN_SEED): the hidden suite is built from "
            f"the PUBLIC DEVELOPMENT SEED {seed}.\nAnyone can rebuild these scenarios. Fine "
            "for a demo, never for a competition.",
            title="[bold red]WARNING[/bold red]",
            border_style="red",
        )
    )


def _demo_team_token(storage: StorageSettings, name: str) -> str:
    """The demo team's token, the same across restarts: kept for the local organiser in the data
    folder (owner-readable only; the database stores tokens hashed). A token that no longer
    works (revoked with `teams rotate-token`) is replaced."""
    stored = storage.resolved_data_dir / "demo_token"
    db = Database(storage.resolved_database_url)
    try:
        with db.session() as session:
            if stored.exists():
                token = stored.read_text().strip()
                team = teams.team_for_token(session, token)
                if team is not None and team.name == name:
                    return token
            try:
                token = teams.rotate_token(session, teams.get_team(session, name))
            except NotFound:
                token = teams.create_team(session, name)[1]
    finally:
        db.dispose()
    stored.write_text(token + "\n")
    stored.chmod(0o600)
    return token


def _wait_healthy(url: str, children: list[subprocess.Popen], timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if any(child.poll() is not None for child in children):
            raise RuntimeError("a service process exited during start-up")
        try:
            if httpx.get(url, timeout=2.0).status_code == 200:
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.3)
    raise RuntimeError(f"the API did not become healthy within {timeout_s:.0f} s")


def _stop(console: Console, children: list[subprocess.Popen]) -> None:
    """SIGTERM to every child at once, then one shared grace: Ctrl-C answers within
    :data:`STOP_GRACE_S` however many children are slow (each waited in turn would add up)."""
    for child in children:
        if child.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(child.pid, signal.SIGTERM)
    deadline = time.monotonic() + STOP_GRACE_S
    for child in children:
        try:
            child.wait(timeout=max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            console.print(
                f"`{' '.join(child.args[3:])}` did not stop within {STOP_GRACE_S:g} s: killed"
            )
            with contextlib.suppress(ProcessLookupError):
                os.killpg(child.pid, signal.SIGKILL)
            child.wait()
