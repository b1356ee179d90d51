"""Fixtures of the core's unit tests (no ROS here)."""
from __future__ import annotations

import matplotlib
import pytest

import realdata

matplotlib.use("Agg")


def pytest_report_header() -> str:
    """Say where the real datasets were found, or why the tests that read them will skip."""
    found = realdata.find_datasets()
    return f"real datasets: {found}" if found is not None else f"real datasets: none ({realdata.MISSING})"


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """A test that fails only because the real datasets are absent is reported as skipped, with the reason.

    Applies only when no datasets directory was found at all and the error names a path
    inside the placeholder directory (which exists nowhere), so a missing file in a present
    directory still fails.
    """
    outcome = yield
    report = outcome.get_result()
    if call.excinfo is None or report.passed or realdata.find_datasets() is not None:
        return
    if str(realdata.datasets_dir()) in str(call.excinfo.value):
        report.outcome = "skipped"
        report.longrepr = (str(item.path), item.location[1] or 0, f"Skipped: {realdata.MISSING}")
