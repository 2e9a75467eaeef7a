"""Fixtures of the DDS integration tests: one domain and one set of children per test."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from graph_utils import Children, ros_env, unique_domain_id


@pytest.hookimpl(wrapper=True, tryfirst=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo) -> Iterator[None]:
    """Remember each phase's report on the item, so fixtures know whether the test failed."""
    report = yield
    setattr(item, f"report_{report.when}", report)
    return report


@pytest.fixture
def children(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Children]:
    """Children on a domain of their own; all stopped at teardown, their logs shown on failure."""
    log_dir = tmp_path / "logs"
    kids = Children(ros_env(unique_domain_id(), log_dir), log_dir)
    try:
        yield kids
    finally:
        kids.close()
        report = getattr(request.node, "report_call", None)
        if report is not None and report.failed:
            print(f"ROS_DOMAIN_ID={kids.domain_id}\n{kids.all_logs()}")
