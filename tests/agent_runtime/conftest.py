"""The compat packages (``smarts``, ``gym``) importable by these tests, as the sandbox makes them
for a ``smarts2022`` policy: importing the converter puts ``agent_runtime/compat`` on sys.path."""

import agent_runtime.smarts_compat  # noqa: F401
