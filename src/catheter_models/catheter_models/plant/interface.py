"""The plant contract: any simulator behind the simulated rig, loaded by ``module:factory``.

A plant is given by an import path, ``module:factory`` or ``path/to/file.py:factory``. The
factory is called with no arguments and returns an object with

* ``rate_hz`` (float): the plant's sample rate, which the rig runs at;
* ``reset()``: back to rest;
* ``step(pressure_command_pa) -> (pressure_measured_pa, bend_rad)``: one sample later, noise
  included.

The shipped simulator (:class:`~catheter_models.plant.simulator.Plant`) meets it through
:class:`ShippedPlant` and stays the default. :func:`make_plant` loads a plant and checks it
(:class:`CheckedPlant`): a plant that cannot be loaded, breaks the contract, returns a
non-finite value or cannot keep its rate is refused (:class:`PlantError`) or stopped
(:class:`PlantRunError`) with the reason. See docs/simulated_rig.md, "Your own plant".
"""

from __future__ import annotations

import importlib
import importlib.util
import math
import numbers
import re
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Final, Protocol, runtime_checkable

import numpy as np

from catheter_models.errors import CatheterError
from catheter_models.geometry import LaserGeometry
from catheter_models.plant.config import RIG_PARAMS, PlantConfig
from catheter_models.plant.simulator import _LASER_VOLTAGE_RANGE_V, Plant, PlantSample

_RATE_SPEC: Final = next(p for p in RIG_PARAMS if p.name == "sample_rate_hz")
RATE_RANGE_HZ: Final = (_RATE_SPEC.low, _RATE_SPEC.high)
"""Sample rates the rig runs at: the range of ``rig.sample_rate_hz`` [Hz]."""

RATE_WINDOW_S: Final = 1.0
"""Plant time over which a plant must keep its rate [s] (see :class:`CheckedPlant`)."""

PROBE_STEPS: Final = 25
"""Timed steps at rest with which :meth:`CheckedPlant.probe` checks a plant before it runs."""
PROBE_BUDGET_S: Final = 0.5
"""Longest the probe's timed steps may take together [s]; it stops timing after that."""

FOREIGN_RIG_PARAMS: Final = ("ambient_pressure_pa", "straight_distance_m")
"""Rig settings that apply to any plant: the pressure messages' ambient and the laser's
straight-tip distance, from which ``tip/distance`` is derived. Every other rig setting, each
effect and the seed are the shipped plant's own."""


class PlantError(CatheterError):
    """A plant cannot be used: bad spec, import failure, factory failure, broken contract."""


class PlantRunError(CatheterError):
    """A running plant broke its contract (raised, non-finite, too slow) and was stopped."""


@runtime_checkable
class PlantModel(Protocol):
    """What a plant of your own provides (docs/simulated_rig.md, "Your own plant")."""

    @property
    def rate_hz(self) -> float:
        """The plant's sample rate [Hz]: one :meth:`step` is one period of it."""
        ...

    def reset(self) -> None:
        """Back to rest: vented muscle, straight tip."""
        ...

    def step(self, pressure_command_pa: float) -> tuple[float, float]:
        """Hold the command (gauge [Pa]) for one period.

        Returns ``(pressure_measured_pa, bend_rad)`` at its end, noise included.
        """
        ...


class ShippedPlant:
    """The shipped simulator in the contract (and its full samples for the rig).

    ``step`` gives the transmitter's reading and the laser's bend of
    :meth:`Plant.step <catheter_models.plant.simulator.Plant.step>`; :meth:`step_sample` the
    whole sample (laser distance, truth), which the rig publishes unchanged.
    """

    def __init__(self, config: PlantConfig) -> None:
        self.plant = Plant(config)
        self.rate_hz = float(config.rig["sample_rate_hz"])

    def warm_up(self) -> None:
        """Compile the kernel now (see :meth:`Plant.warm_up`)."""
        self.plant.warm_up()

    def reset(self) -> None:
        """Back to rest, noise re-seeded: the same samples again from here."""
        self.plant.reset()

    def step(self, pressure_command_pa: float) -> tuple[float, float]:
        """The contract's step: ``(pressure_measured_pa, bend_rad)``."""
        sample = self.plant.step(pressure_command_pa)
        return sample.pressure_measured_pa, sample.angle_rad

    def step_sample(self, pressure_command_pa: float) -> PlantSample:
        """One sample with every field (what :meth:`Plant.step` gives)."""
        return self.plant.step(pressure_command_pa)


# -- loading -------------------------------------------------------------------------------


def _describe(value: object) -> str:
    text = repr(value)
    return f"{type(value).__name__} {text[:80]}{'...' if len(text) > 80 else ''}"


def parse_spec(spec: str) -> tuple[str, str, bool]:
    """``(module or file, factory, is_file)`` of a plant spec; PlantError if malformed."""
    where, sep, factory = spec.strip().rpartition(":")
    usage = (
        f"plant {spec!r} is not 'module:factory' or 'path/to/file.py:factory' "
        "(e.g. my_lab.rod:make_plant)"
    )
    if not sep or not where or not factory:
        raise PlantError(usage)
    if not all(part.isidentifier() for part in factory.split(".")):
        raise PlantError(f"{usage}: {factory!r} is not a Python name")
    is_file = where.endswith(".py") or "/" in where
    if not is_file and not all(part.isidentifier() for part in where.split(".")):
        raise PlantError(f"{usage}: {where!r} is not a module path")
    return where, factory, is_file


def _import_file(path_text: str) -> Any:
    path = Path(path_text).expanduser()
    if not path.is_file():
        raise PlantError(
            f"plant file {path_text!r} does not exist (relative paths are taken from the "
            f"working directory, {Path.cwd()})"
        )
    # A name of its own per file, registered before it runs (dataclasses and pickling look
    # their module up in sys.modules) and removed again if it fails.
    name = "_catheter_plant_" + re.sub(r"\W", "_", str(path.resolve()))
    module_spec = importlib.util.spec_from_file_location(name, path)
    if module_spec is None or module_spec.loader is None:
        raise PlantError(f"plant file {path_text!r} cannot be loaded as Python")
    module = importlib.util.module_from_spec(module_spec)
    sys.modules[name] = module
    try:
        module_spec.loader.exec_module(module)
    except Exception as exc:
        del sys.modules[name]
        raise PlantError(
            f"loading plant file {path_text!r} raised {type(exc).__name__}: {exc}"
        ) from exc
    return module


def _import_module(name: str) -> Any:
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as exc:
        if exc.name is not None and (name == exc.name or name.startswith(f"{exc.name}.")):
            raise PlantError(
                f"plant module {name!r} not found (no module named {exc.name!r}): is its "
                "directory on PYTHONPATH?"
            ) from exc
        raise PlantError(f"importing plant module {name!r} failed: {exc}") from exc
    except Exception as exc:
        raise PlantError(
            f"importing plant module {name!r} raised {type(exc).__name__}: {exc}"
        ) from exc


def check_contract(plant: object, name: str) -> float:
    """The plant's ``rate_hz`` if it meets the contract's shape; PlantError naming what not."""
    problems = []
    rate = getattr(plant, "rate_hz", None)
    for method in ("reset", "step"):
        if not callable(getattr(plant, method, None)):
            problems.append(f"no {method}() method")
    if rate is None:
        problems.append("no rate_hz")
    elif isinstance(rate, bool) or not isinstance(rate, numbers.Real):
        problems.append(f"rate_hz is {_describe(rate)}, not a number")
    if problems:
        raise PlantError(
            f"plant {name} returned {_describe(plant)}, which does not meet the plant contract "
            f"(rate_hz, reset(), step(pressure_command_pa) -> (pressure_measured_pa, bend_rad)): "
            + "; ".join(problems)
        )
    rate_hz = float(rate)  # type: ignore[arg-type]
    low, high = RATE_RANGE_HZ
    if not (math.isfinite(rate_hz) and low <= rate_hz <= high):
        raise PlantError(
            f"plant {name}: rate_hz = {rate_hz!r} is outside the rates the rig runs at "
            f"[{low:g}, {high:g}] Hz"
        )
    return rate_hz


def load_plant(spec: str) -> PlantModel:
    """Import ``module:factory`` (or ``path/to/file.py:factory``), call it, check its shape.

    Raises:
        PlantError: the spec is malformed, the module or file or the factory is not found,
            importing or calling it raised, or what it returned lacks ``rate_hz`` (a number
            in :data:`RATE_RANGE_HZ`), ``reset()`` or ``step()``. The message says which.
    """
    where, factory_name, is_file = parse_spec(spec)
    module = _import_file(where) if is_file else _import_module(where)
    factory: Any = module
    for part in factory_name.split("."):
        if not hasattr(factory, part):
            raise PlantError(f"plant {spec!r}: {where!r} has no attribute {factory_name!r}")
        factory = getattr(factory, part)
    if not callable(factory):
        raise PlantError(f"plant {spec!r}: {factory_name} is {_describe(factory)}, not callable")
    try:
        plant = factory()
    except Exception as exc:
        raise PlantError(f"plant factory {spec!r} raised {type(exc).__name__}: {exc}") from exc
    check_contract(plant, repr(spec))
    return plant  # type: ignore[no-any-return]


# -- checking ------------------------------------------------------------------------------


class CheckedPlant:
    """A plant run under the contract's checks, giving the rig whole samples.

    Every step is checked: a step that raises, returns something other than two real
    numbers, or a non-finite one raises :class:`PlantRunError` with the reason. The plant must
    keep its rate: over each :data:`RATE_WINDOW_S` of plant time (``rate_hz`` steps) its
    steps may take no longer, in wall time all told, than that window spans. This is what
    "persistently" means: a single slow step (a garbage collection, a busy host) is absorbed
    by the rig's catch-up, but a plant that spends more than a second on a second of samples
    runs slower than real time on average and falls further behind with every window, so it
    is stopped. A single step still running after a whole window (:meth:`stuck_for_s`) is
    the same failure, caught while it runs.

    For a plant of your own, ``tip/distance`` is derived from the bend with the laser
    geometry (inverse of eqs. 3.1-3.3, at the rig's straight-tip distance, clipped to the
    laser's 0-10 V range as the shipped laser clips), and the truth fields of the sample
    (``true_angle_rad``, ``muscle_pressure_pa``) are NaN: such a plant gives no truth.

    Args:
        plant: the plant (a :class:`ShippedPlant` gives its own full samples).
        name: how messages name it (the quoted spec, or "(the shipped plant)").
        straight_distance_m: laser distance with the tip straight [m].
        geometry: laser geometry (thesis constants by default).
        clock: the wall clock the timing is measured on [s].
    """

    def __init__(
        self,
        plant: PlantModel,
        name: str,
        straight_distance_m: float,
        geometry: LaserGeometry | None = None,
        clock: Callable[[], float] = time.perf_counter,
    ) -> None:
        self.plant = plant
        self.name = name
        self.rate_hz = check_contract(plant, name)
        self.period_s = 1.0 / self.rate_hz
        self.geometry = geometry if geometry is not None else LaserGeometry()
        self.straight_distance_m = straight_distance_m
        self._clock = clock
        self._window_steps = max(1, round(RATE_WINDOW_S * self.rate_hz))
        self._window_used_s = 0.0
        self._window_n = 0
        self._n_samples = 0
        self._step_started_s: float | None = None
        self._full = plant.step_sample if isinstance(plant, ShippedPlant) else None

    @property
    def shipped(self) -> bool:
        """Whether this is the shipped simulator."""
        return self._full is not None

    def reset(self) -> None:
        """Back to rest (the plant's reset), time zero, timing forgotten."""
        try:
            self.plant.reset()
        except Exception as exc:
            raise PlantRunError(
                f"plant {self.name}: reset() raised {type(exc).__name__}: {exc}"
            ) from exc
        self._n_samples = 0
        self._window_used_s = 0.0
        self._window_n = 0

    def probe(self) -> None:
        """Check the plant before it runs: reset, steps at rest, timed, then reset again.

        The first step is not timed (a JIT-compiled plant compiles on it). Up to
        :data:`PROBE_STEPS` more are, for at most :data:`PROBE_BUDGET_S`; their mean must fit
        in a period.

        Raises:
            PlantError: a step failed its checks, or the plant is slower than its rate.
        """
        try:
            self.reset()
            self.step_sample(0.0)
            used_s, n = 0.0, 0
            while n < PROBE_STEPS and used_s < PROBE_BUDGET_S:
                start = self._clock()
                self.step_sample(0.0)
                used_s += self._clock() - start
                n += 1
            self.reset()
        except PlantRunError as exc:
            raise PlantError(str(exc)) from exc
        if used_s > n * self.period_s:
            raise PlantError(
                f"plant {self.name} cannot keep its rate: {used_s / n * 1e3:.3f} ms per step at "
                f"rest (mean of {n}), longer than its period of {self.period_s * 1e3:.3f} ms "
                f"at {self.rate_hz:g} Hz"
            )

    def stuck_for_s(self, now_s: float | None = None) -> float:
        """How long the step in progress has run [s] (0 if none is)."""
        started = self._step_started_s
        if started is None:
            return 0.0
        return (self._clock() if now_s is None else now_s) - started

    def stuck_reason(self) -> str:
        """Why the plant counts as too slow right now ('' if it does not).

        It does when a step has been in progress for longer than :data:`RATE_WINDOW_S`.
        """
        stuck_s = self.stuck_for_s()
        if stuck_s <= RATE_WINDOW_S:
            return ""
        return (
            f"plant {self.name} cannot keep its rate: one step has run for {stuck_s:.2f} s, "
            f"more than {RATE_WINDOW_S:g} s of plant time at {self.rate_hz:g} Hz"
        )

    def step_sample(self, pressure_command_pa: float) -> PlantSample:
        """One checked step; the whole sample the rig publishes.

        Raises:
            PlantRunError: the step raised, returned no ``(float, float)``, a non-finite value,
                or the plant fell behind its rate (see the class docstring).
        """
        k = self._n_samples + 1
        start = self._clock()
        self._step_started_s = start
        try:
            if self._full is not None:
                full = self._full(pressure_command_pa)
                out: object = (full.pressure_measured_pa, full.angle_rad)
            else:
                full = None
                out = self.plant.step(pressure_command_pa)
        except Exception as exc:
            raise PlantRunError(
                f"plant {self.name}: step() raised {type(exc).__name__} at sample {k}: {exc}"
            ) from exc
        finally:
            self._step_started_s = None
        used_s = self._clock() - start
        pressure_pa, bend_rad = self._check_output(out, k)
        self._n_samples = k
        self._keep_rate(used_s)
        if full is not None:
            return full
        return PlantSample(
            t_s=k * self.period_s,
            pressure_command_pa=float(pressure_command_pa),
            pressure_measured_pa=pressure_pa,
            distance_m=self.distance_m(bend_rad),
            angle_rad=bend_rad,
            true_angle_rad=math.nan,
            muscle_pressure_pa=math.nan,
        )

    def _check_output(self, out: object, k: int) -> tuple[float, float]:
        shape = "(pressure_measured_pa, bend_rad)"
        if not isinstance(out, tuple | list) or len(out) != 2:
            raise PlantRunError(
                f"plant {self.name}: step() returned {_describe(out)} at sample {k}, not {shape}"
            )
        values = []
        for field, value in zip(("pressure_measured_pa", "bend_rad"), out, strict=True):
            if isinstance(value, bool) or not isinstance(value, numbers.Real):
                raise PlantRunError(
                    f"plant {self.name}: step() returned {field} = {_describe(value)} at sample "
                    f"{k}, not a number"
                )
            number = float(value)
            if not math.isfinite(number):
                raise PlantRunError(
                    f"plant {self.name}: step() returned a non-finite {field} ({number!r}) at "
                    f"sample {k}"
                )
            values.append(number)
        return values[0], values[1]

    def _keep_rate(self, used_s: float) -> None:
        self._window_used_s += used_s
        self._window_n += 1
        if self._window_n < self._window_steps:
            return
        used, n = self._window_used_s, self._window_n
        self._window_used_s, self._window_n = 0.0, 0
        if used > n * self.period_s:
            raise PlantRunError(
                f"plant {self.name} cannot keep its rate: its last {n} steps "
                f"({n * self.period_s:.3g} s of plant time) took {used:.3g} s, "
                f"{used / n * 1e3:.3f} ms per step against a period of "
                f"{self.period_s * 1e3:.3f} ms"
            )

    def distance_m(self, bend_rad: float) -> float:
        """The laser distance a bend gives (inverse eqs. 3.3, 3.2, 3.1's range) [m].

        The bend is capped short of eq. 3.3's fold (about 68 deg) and the distance clipped
        to what the laser's 0-10 V output reaches, as the shipped plant's laser does.
        """
        geom = self.geometry
        reachable = min(abs(bend_rad), 0.999 * geom.max_angle_rad)
        displacement_m = math.copysign(float(geom.angle_to_displacement_m(reachable)), bend_rad)
        low_v, high_v = _LASER_VOLTAGE_RANGE_V
        voltage_v = float(
            np.clip(
                geom.distance_to_voltage_v(self.straight_distance_m - displacement_m), low_v, high_v
            )
        )
        return float(geom.voltage_to_distance_m(voltage_v))


# -- choosing ------------------------------------------------------------------------------


def shipped_only_settings(config: PlantConfig, rate_hz: float) -> list[str]:
    """Settings in ``config`` that only the shipped plant honours, set away from the default.

    A plant of your own takes none of them (only :data:`FOREIGN_RIG_PARAMS` apply); so that
    none is dropped silently, each is named. ``sample_rate_hz`` may be set, to the plant's
    own ``rate_hz``.
    """
    default = PlantConfig.thesis_rig()
    names = []
    for key, value in config.rig.items():
        if key in FOREIGN_RIG_PARAMS or value == default.rig[key]:
            continue
        if key == "sample_rate_hz" and value == rate_hz:
            continue
        names.append(f"rig.{key}")
    for name, setting in config.effects.items():
        base = default.effects[name]
        if setting.enabled != base.enabled:
            names.append(f"effects.{name}.enabled")
        names.extend(
            f"effects.{name}.{p}" for p, v in setting.params.items() if v != base.params[p]
        )
    if config.seed != default.seed:
        names.append("seed")
    return names


def make_plant(
    spec: str, config: PlantConfig, geometry: LaserGeometry | None = None
) -> CheckedPlant:
    """The plant the rig runs, checked and probed at rest: ``spec`` '' is the shipped one.

    Args:
        spec: ``module:factory``, ``path/to/file.py:factory``, or '' for the shipped plant.
        config: the rig's settings: the shipped plant's whole configuration; for a plant of
            your own only :data:`FOREIGN_RIG_PARAMS` (and a ``sample_rate_hz`` equal to its
            rate) may differ from the defaults.
        geometry: laser geometry (thesis constants by default).

    Raises:
        PlantError: the plant cannot be loaded, breaks the contract at rest, cannot keep its
            rate, or ``config`` sets what it does not take. The message says which.
    """
    straight_m = float(config.rig["straight_distance_m"])
    if not spec.strip():
        shipped = ShippedPlant(config)
        shipped.warm_up()
        checked = CheckedPlant(shipped, "(the shipped plant)", straight_m, shipped.plant.geometry)
    else:
        plant = load_plant(spec)
        checked = CheckedPlant(plant, repr(spec.strip()), straight_m, geometry)
        ignored = shipped_only_settings(config, checked.rate_hz)
        if ignored:
            raise PlantError(
                f"plant {spec!r} is your own, so these settings of the shipped plant would be "
                f"ignored: {', '.join(ignored)}; leave them unset (it runs at its own rate_hz "
                f"= {checked.rate_hz:g} Hz)"
            )
    checked.probe()
    return checked
