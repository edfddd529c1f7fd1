"""A compatibility subset of SMARTS (Driving SMARTS 2022 era) for agents run by Driving Arena.

Only what an agent reads or imports at run time: the simulator is Driving Arena's. See
``docs/smarts-compat.md`` for what differs from SMARTS.
"""

VERSION = "0.6.1+arena"
__version__ = VERSION
