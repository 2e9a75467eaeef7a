"""What every hysteresis core is, and the helpers cores share.

The :class:`Core` contract, the rate filter, BLAS on one thread, and a thesis model's
parameter table as a core (:class:`_ThesisCore`).
"""

from __future__ import annotations

import functools
import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar, Final, ParamSpec, TypeVar

import numpy as np
import numpy.typing as npt
from threadpoolctl import threadpool_limits

from catheter_models.errors import ParameterError
from catheter_models.models.base import ModelError, Recording
from catheter_models.units import bar_to_pa, deg_to_rad

FloatArray = npt.NDArray[np.float64]
Step = Callable[[float], float]

RATE_FILTER_S: Final = 0.02
"""Low-pass time constant of the rate estimate that rate-dependent thresholds use [s]."""

TENSION_REF_BAR: Final = 1.5
"""Pressure at which ``free_pi``'s play thresholds are their nominal ``r_i`` [bar] (mid-range)."""

TENSION_SCALE_MAX: Final = 2.0
"""Cap of the thresholds' growth with pressure (at twice the reference pressure)."""


P = ParamSpec("P")
R = TypeVar("R")


def one_blas_thread(func: Callable[P, R]) -> Callable[P, R]:
    """Run ``func`` with BLAS on one thread.

    The lab's matrices (tens of thousands of rows, tens to a hundred columns) gain little
    from a second BLAS thread, and OpenBLAS's threads spin while they wait: on a 2-core lab
    PC with anything else running, a free_pi fit took 58 s with two BLAS threads against
    3.4 s with one (measured beside another identification).
    """

    @functools.wraps(func)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        with threadpool_limits(limits=1, user_api="blas"):
            return func(*args, **kwargs)

    return wrapper


def _alpha(rate_hz: float, tau_s: float = RATE_FILTER_S) -> float:
    return 1.0 - math.exp(-1.0 / (rate_hz * tau_s))


class Core(ABC):
    """A hysteresis law from pressure [bar] to bend [deg], fitted from data."""

    name: ClassVar[str]
    summary: ClassVar[str]
    linear: ClassVar[bool] = False
    """True when the output is linear in the weights for fixed structure parameters: the
    grey box then refits it exactly by least squares inside every block search."""

    @abstractmethod
    def settings(self) -> dict[str, Any]:
        """The structure (not the fitted values), as the model file stores it."""

    @abstractmethod
    def fit(
        self, xs: Sequence[FloatArray], ys: Sequence[FloatArray], rate_hz: float, **kw: Any
    ) -> None:
        """Identify from scratch on pressure [bar] and bend [deg] recordings."""

    @abstractmethod
    def run(self, x: FloatArray, rate_hz: float) -> FloatArray:
        """Bend [deg] for pressure ``x`` [bar] from rest."""

    @abstractmethod
    def streamer(self, rate_hz: float) -> Step:
        """``run`` one sample at a time, equal to it."""

    @abstractmethod
    def values(self) -> dict[str, Any]:
        """The fitted values, JSON-ready."""

    @abstractmethod
    def load_values(self, values: Mapping[str, Any]) -> None:
        """Set fitted values read from a model file (ModelError if malformed)."""

    @property
    @abstractmethod
    def fitted(self) -> bool:
        """Whether the core has values."""

    def copy(self) -> Core:
        """An independent copy with the same structure and values."""
        new = type(self)(**self.settings())
        if self.fitted:
            new.load_values(self.values())
        return new

    # Nonlinear cores are polished jointly with the blocks over a bounded vector.
    def vector(self) -> FloatArray:
        """The values as a vector for a joint least-squares polish."""
        raise NotImplementedError

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        """Lower and upper bounds of :meth:`vector`."""
        raise NotImplementedError

    def runner(self, v: FloatArray, rate_hz: float) -> Callable[[FloatArray], FloatArray] | None:
        """A function running the core with vector ``v`` (None if ``v`` is not admissible)."""
        raise NotImplementedError

    def set_vector(self, v: FloatArray) -> None:
        """Adopt the polished vector ``v``."""
        raise NotImplementedError


def _recordings(xs: Sequence[FloatArray], ys: Sequence[FloatArray], rate_hz: float) -> list[Any]:
    """The chain's bar/deg arrays as SI Recordings, for a thesis model's own identification."""
    return [
        Recording(f"r{i}", rate_hz, bar_to_pa(x), deg_to_rad(y))
        for i, (x, y) in enumerate(zip(xs, ys, strict=True))
    ]


class _ThesisCore(Core):
    """A core whose parameters are a thesis model's parameter table (DRDPI, GPI).

    The table's own ``to_dict``/``from_dict`` are what the model file holds.
    """

    params: Any = None

    @abstractmethod
    def _params_type(self) -> Any:
        """The parameter table's class."""

    @property
    def fitted(self) -> bool:
        """Whether parameters are set."""
        return self.params is not None

    def set_params(self, params: Any) -> None:
        """Adopt a parameter table (e.g. a fitted thesis model's)."""
        self.params = params

    def values(self) -> dict[str, Any]:
        """The table's parameters by name."""
        if self.params is None:
            raise ModelError(f"{self.name} core is not fitted")
        out: dict[str, Any] = self.params.to_dict()
        return out

    def load_values(self, values: Mapping[str, Any]) -> None:
        """The table's parameters from a model file."""
        try:
            self.set_params(self._params_type().from_dict(dict(values)))
        except (KeyError, TypeError, ValueError, ParameterError) as exc:
            raise ModelError(f"{self.name} core values are malformed: {exc}") from None
