"""The top-level packages Driving SMARTS 2022 agents import, for ``observation_format: smarts2022``.

This folder (not the runtime's own) goes on the policy's ``sys.path``, after the submission and
its dependency folder, so a participant who ships the real ``smarts`` or ``gym`` gets theirs:

- ``smarts``: the observation types, coordinates, math utilities, road map ``Waypoint``,
  ``ActionSpaceType``, agent interface and the competition kit's ``FormatObs`` / ``FormatAction``
  / ``FrameStack`` wrappers, written from SMARTS's documented behaviour (v0.6, ``comp-1``);
- ``gym``: the small part of gym 0.21 those wrappers and agents use (``Env``, the wrappers,
  ``spaces``).

``docs/smarts-compat.md`` lists every difference from SMARTS. Standard library and numpy only.
"""
