import os
import sys

# Two intra-op threads for torch (and OpenBLAS) whatever the machine's core count: a parallel reduction's result
# depends on how many threads split it, and the suite's numbers were measured on 2 cores. Both libraries read this
# when they first start their thread pools, so it is set before anything imports them and without importing torch
# here: the torch-free tests (and the CLI subprocesses, which inherit it) never pay torch's 1.1 s import.
os.environ["OMP_NUM_THREADS"] = "2"

import numpy as np  # noqa: E402
import pytest  # noqa: E402


@pytest.fixture
def rng():
    return np.random.default_rng(0)


def pytest_runtest_setup(item):
    """A test module that imported torch runs with 2 threads even where OMP_NUM_THREADS was read earlier."""
    torch = sys.modules.get("torch")
    if torch is not None and torch.get_num_threads() != 2:
        torch.set_num_threads(2)
