"""A pytest plugin: which of the suite's runs are large enough to meet the compiled rounds' limit.

Every run of the parallel scheduler in the test processes on more than 131,072 faces (the limit before it was
raised to `selection.MAX_FACES`) is written, with the test that made it, its face count and the path it took
(True: the compiled rounds), to the file named by ``QEMJAX_SUITE_PATHS`` (default ``suite_paths.txt`` in the
working folder). Runs in processes a test starts (a partitioned run's workers, a sweep's helpers) are not seen.

    PYTHONPATH=experiments/probes python -m pytest -q -p suite_paths
"""
from __future__ import annotations

import os

import pytest

SINCE = 1 << 17  # the limit before
_test = {"id": None}


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item):
    _test["id"] = item.nodeid


def pytest_configure(config):
    from qemjax._schedulers.parallel import selection

    fits, out = selection.fits, os.environ.get("QEMJAX_SUITE_PATHS", "suite_paths.txt")

    def logged(manifold, incremental, locks, faces):
        took = fits(manifold, incremental, locks, faces)
        if faces > SINCE:
            with open(out, "a") as f:
                f.write(f"{_test['id']}\t{faces}\t{took}\n")
        return took
    selection.fits = logged
