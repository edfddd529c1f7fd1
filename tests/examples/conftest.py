"""The example agents' tests train and run the PPO example on the environments' short road."""

from tests.learn.conftest import short_road  # noqa: F401  (a fixture, shared with the env tests)
