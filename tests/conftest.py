import os
import sys

import numpy as np
import pytest

# Tests run against the in-place build (`make build`) unless told otherwise:
# `make test-asan` points LMREFINE_PYTHONPATH at the sanitized build.
sys.path.insert(0, os.environ.get("LMREFINE_PYTHONPATH",
                                  os.path.join(os.path.dirname(__file__), "..", "python")))


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


def pytest_configure(config):
    config.addinivalue_line("markers", "blender: drives real headless Blender")
    config.addinivalue_line("markers", "slow: takes more than a few seconds")
