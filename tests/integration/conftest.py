"""Fixtures of the DDS integration tests: one domain and one set of children per test."""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from fault_log import FaultRecord, write_report
from graph_utils import Children, ros_env, unique_domain_id

_FAULTS: list[FaultRecord] = []


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


@pytest.fixture
def fault(request: pytest.FixtureRequest) -> Iterator[FaultRecord]:
    """The fault this test injects (from its ``fault`` marker), recorded for the table."""
    marker = request.node.get_closest_marker("fault")
    if marker is None:
        raise pytest.UsageError(f"{request.node.nodeid} takes `fault` but has no fault marker")
    record = FaultRecord(
        test=request.node.nodeid,
        fault=str(marker.args[0]),
        safe=str(marker.kwargs.get("safe", "")),
        category=str(marker.kwargs.get("category", "graph")),
    )
    start = time.monotonic()
    try:
        yield record
    finally:
        record.duration_s = time.monotonic() - start
        report = getattr(request.node, "report_call", None)
        record.outcome = "not run" if report is None else report.outcome
        _FAULTS.append(record)


def pytest_configure(config: pytest.Config) -> None:
    """Children must start with SIGINT at its default, whoever started the suite.

    A suite started in the background by a non-interactive shell (``make test &``, nohup, some
    CI runners) inherits SIGINT ignored; an ignored signal stays ignored across exec, and
    Python keeps it so: the tests that stop a tool with SIGINT, as Ctrl-C does, saw it run on
    (two failures in a clean-clone run started that way). A handled signal is reset to its
    default in every child at exec, so handling it here is enough.
    """
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """With FAULT_REPORT set, write the rows of every fault test that ran."""
    path = os.environ.get("FAULT_REPORT")
    if path and _FAULTS:
        write_report(_FAULTS, Path(path))
