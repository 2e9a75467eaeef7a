"""Two rules every layer that can move the catheter shares, kept where a reader looks for them.

* :class:`BoundedParam`: a parameter's name (with its unit), default, closed range and
  meaning; a value outside the range is refused by name. The nodes' parameters and the
  plant's effect strengths are declared with it. The contract's numbers that the ranges use
  (pressure ceilings, rates) are in :mod:`catheter_models.contract`.
* :func:`limit_window`: where the next pressure command may go, the clamp and the slew limit
  together, for the compensator's loop and the offline closed loop alike.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from catheter_models.errors import ParameterError


@dataclass(frozen=True)
class BoundedParam:
    """One physical parameter: name with unit suffix, default, closed range and meaning.

    Every node declares its parameters with one (``catheter_ros.params``), and the plant its
    effects' strengths, so a value is checked against the same range wherever it enters.
    """

    name: str
    default: float
    low: float
    high: float
    doc: str

    def check(self, value: float, owner: str) -> float:
        """Return ``value`` as float if finite and within range, else raise ParameterError."""
        value = float(value)
        if not math.isfinite(value) or not self.low <= value <= self.high:
            raise ParameterError(
                f"{owner}.{self.name} = {value!r} is outside its range "
                f"[{self.low:g}, {self.high:g}] ({self.doc})"
            )
        return value


def limit_window(
    last_pa: float, floor_pa: float, ceiling_pa: float, max_step_pa: float
) -> tuple[float, float]:
    """Where the next command may go: the clamp, and at most ``max_step_pa`` from the last.

    One rule for the node's :class:`~catheter_control.control_core.ControlCore` and for
    :class:`~catheter_models.feedback.law.ClosedLoop`, with or without feedback. A last
    command outside the clamp (a ceiling lowered mid-run) walks back at the slew limit rather
    than jumping.
    """
    low = max(floor_pa, last_pa - max_step_pa)
    high = min(ceiling_pa, last_pa + max_step_pa)
    if low > high:
        # Outside the clamp: move toward it by one step.
        nearest = min(max(last_pa, floor_pa), ceiling_pa)
        low = high = min(max(nearest, last_pa - max_step_pa), last_pa + max_step_pa)
    return low, high
