"""The lab's slow tests fit dozens of models: their timeout catches a hang, not slowness.

pytest's default (300 s, pyproject.toml) is a hang detector sized for the rest of the suite.
``test_nothing_hidden_names_no_effect_and_calls_the_drdpi_law_the_miss`` took 52 s with numba's
kernels cached and 126 s on a fresh clone (every kernel compiled first) on this 2-core machine
with other work on it, and went past 300 s in CI beside two busy loops. What these tests
assert is the lab's verdict, which does not depend on the time taken: the searches stop by
generations, evaluations or convergence (``identify`` starts its wall-clock ceiling after the
kernels are compiled). So a slow lab test gets :data:`LAB_TIMEOUT_S` unless it sets its own.
"""

from __future__ import annotations

from pathlib import Path

import pytest

LAB_TIMEOUT_S = 1200.0
_HERE = Path(__file__).resolve().parent


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if (
            Path(str(item.fspath)).resolve().parent == _HERE
            and item.get_closest_marker("slow") is not None
            and item.get_closest_marker("timeout") is None
        ):
            item.add_marker(pytest.mark.timeout(LAB_TIMEOUT_S))
