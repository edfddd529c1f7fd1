"""Where later SMARTS releases keep the observation types (``smarts.core.observations``)."""

from smarts.core.sensors import *  # noqa: F403
from smarts.core.sensors import __all__  # noqa: F401
