import pytest

from tests.predictors.samples import shared_data_dir


@pytest.fixture(autouse=True)
def _private_cache(tmp_path_factory, monkeypatch):
    """Keep prepared data and scene caches of the tests out of the user's ~/.cache."""
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path_factory.mktemp("cache")))


@pytest.fixture
def shared_data():
    """The team's shared data directory (raw EWAP + official TrajNet++ files), or skip."""
    root = shared_data_dir()
    if root is None:
        pytest.skip("shared data (../shared/data or $CROWDMPC_DATA) not available")
    return root
