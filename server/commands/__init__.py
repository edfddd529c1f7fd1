"""The service's command lines, one module per resource, as `server/api/routes/` is its HTTP
face: `<resource>.py` drives `server/services/<resource>.py` and holds a Typer app that the
`arena` command (`arena_command/`) mounts. Every module writes through `console.py`."""
