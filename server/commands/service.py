"""The service's own commands, at the top of the `arena` command: `arena serve` (the API and
pages), `arena worker` (a Celery worker) and `arena up` (everything on one machine,
`server/embedded.py`)."""

from __future__ import annotations

from typing import Annotated

import typer

from server.commands.console import console, fail

app = typer.Typer(no_args_is_help=True)


@app.command("serve")
def serve(host: str = "127.0.0.1", port: int = 8000, workers: int = 1) -> None:
    """Run the API and web pages (uvicorn)."""
    # deferred: CLI start-up time
    from functools import partial

    import uvicorn

    from arena.config import ServiceSettings
    from server.core.http import HeaderDeadlineProtocol

    # Its group alone, not get_settings(): that withdraws the secrets' plain variables from this
    # process's environment, which uvicorn's worker processes (--workers above 1, as in the
    # service image) start from: they found a password file without its URL, and stopped.
    service = ServiceSettings()
    uvicorn.run(
        "server.app:create_app",
        factory=True,
        host=host,
        port=port,
        workers=workers,
        # Slow clients hold no worker: headers have a deadline, idle keep-alives end.
        http=partial(HeaderDeadlineProtocol, header_timeout_s=service.http_header_timeout_s),
        timeout_keep_alive=service.http_keep_alive_s,
    )


@app.command("worker")
def worker(
    concurrency: Annotated[
        int | None, typer.Option(help="Scenarios at once (default: jobs).")
    ] = None,
    loglevel: str = "INFO",
) -> None:
    """Run a Celery worker that evaluates submissions."""
    # deferred: CLI start-up time
    from arena.config import get_settings
    from server.core.celery_app import create_celery_app

    app = create_celery_app(get_settings())
    argv = [
        "worker",
        f"--loglevel={loglevel}",
        "-O",
        "fair",
        "--without-mingle",
        "--without-gossip",
    ]
    if concurrency:
        argv.append(f"--concurrency={concurrency}")
    app.worker_main(argv)


@app.command("up")
def up(
    host: str = "127.0.0.1",
    port: int = 8000,
    demo_team: str = "demo",
) -> None:
    """Everything on this machine: database, scenario suites, API and a worker (Ctrl-C stops)."""
    # deferred: CLI start-up time
    from server.embedded import AlreadyServed, run_embedded

    try:
        run_embedded(console, host=host, port=port, demo_team=demo_team)
    except AlreadyServed as exc:
        raise fail(exc) from None
