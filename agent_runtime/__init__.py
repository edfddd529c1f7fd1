"""The code that runs inside the sandbox, beside the participant's policy: the trust wall drawn as a
folder.

Everything here is mounted read-only into every sandbox (at ``/opt/arena``) and started by the
sandbox's own Python: ``main.py`` serves the policy over the protocol (``docs/protocol.md``),
``zygote.py`` is its warm parent, ``packed_waypoints.py`` makes the waypoint dicts of the packed
paths the protocol carries (the simulator makes an in-process agent's with it too),
``smarts_compat.py`` holds the Driving SMARTS 2022 observation converters and ``compat/`` the
``smarts`` and ``gym`` packages that format puts on the policy's path (``docs/smarts-compat.md``).
So it imports nothing of this project (an import-linter contract says so), only the standard
library and numpy; the evaluator finds the folder through :mod:`importlib.resources`.
"""
