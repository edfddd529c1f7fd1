import pytest

from tests.sim.builders import recorded_episode


@pytest.fixture(scope="module")
def episode(tmp_path_factory):
    """(suite folder, record) of one real short episode, shared by a module's tests."""
    return recorded_episode(tmp_path_factory.mktemp("episode"))
