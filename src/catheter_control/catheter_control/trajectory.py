"""Desired-angle trajectories: validation and interpolation on the control clock (no ROS)."""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt
import yaml

from catheter_models.contract import (
    MAX_TRAJECTORY_DURATION_S,
    MAX_TRAJECTORY_FILE_BYTES,
    MAX_TRAJECTORY_POINTS,
)
from catheter_models.errors import SignalError
from catheter_models.signals import check_trajectory, get_preset
from catheter_models.units import deg_to_rad, rad_to_deg

FloatArray = npt.NDArray[np.float64]

_ACCEL_CHECK_RATE_HZ = 100.0
"""Resolution at which desired acceleration is judged (10 ms), whatever the control rate."""


@dataclass(frozen=True)
class TrajectoryLimits:
    """What the catheter may be asked to do.

    Defaults suit the thesis's rig (about 30 deg at 3 bar, test trajectories up to about 1 Hz);
    the size limits are the contract's (``catheter_models.contract``, where they are argued).
    """

    min_angle_rad: float = 0.0
    max_angle_rad: float = deg_to_rad(35.0)
    max_rate_rad_s: float = deg_to_rad(200.0)
    max_accel_rad_s2: float = deg_to_rad(5000.0)
    max_points: int = MAX_TRAJECTORY_POINTS
    max_duration_s: float = MAX_TRAJECTORY_DURATION_S

    def size_error(self, n_points: int) -> str | None:
        """Why ``n_points`` points are too many, or None: checked before anything else costs."""
        if n_points > self.max_points:
            return (
                f"trajectory has {n_points} points, over the limit of {self.max_points} "
                "(MAX_TRAJECTORY_POINTS): split it, or knot it more sparsely"
            )
        return None


def hermite(
    t_s: FloatArray,
    angle_rad: FloatArray,
    velocity_rad_s: FloatArray | None,
    accel_rad_s2: FloatArray | None,
    at_s: FloatArray,
) -> FloatArray:
    """The trajectory between its knots at ``at_s`` (held at the ends).

    As ros2_controllers' joint trajectory controller interpolates: linear with positions
    alone, cubic Hermite with velocities, quintic Hermite with velocities and accelerations
    (continuous acceleration, so a compensator that reads the plan's acceleration sees no
    impulse at every knot).
    """
    at = np.clip(np.asarray(at_s, dtype=float), t_s[0], t_s[-1])
    if velocity_rad_s is None:
        return np.asarray(np.interp(at, t_s, angle_rad), dtype=float)
    i = np.clip(np.searchsorted(t_s, at, side="right") - 1, 0, t_s.size - 2)
    h = t_s[i + 1] - t_s[i]
    s = (at - t_s[i]) / h
    p0, p1 = angle_rad[i], angle_rad[i + 1]
    v0, v1 = velocity_rad_s[i] * h, velocity_rad_s[i + 1] * h
    s2, s3 = s * s, s * s * s
    if accel_rad_s2 is None:
        return np.asarray(
            (2 * s3 - 3 * s2 + 1) * p0
            + (s3 - 2 * s2 + s) * v0
            + (-2 * s3 + 3 * s2) * p1
            + (s3 - s2) * v1,
            dtype=float,
        )
    a0, a1 = accel_rad_s2[i] * h * h, accel_rad_s2[i + 1] * h * h
    s4, s5 = s3 * s, s3 * s2
    return np.asarray(
        (1 - 10 * s3 + 15 * s4 - 6 * s5) * p0
        + (s - 6 * s3 + 8 * s4 - 3 * s5) * v0
        + (0.5 * s2 - 1.5 * s3 + 1.5 * s4 - 0.5 * s5) * a0
        + (0.5 * s3 - s4 + 0.5 * s5) * a1
        + (-4 * s3 + 7 * s4 - 3 * s5) * v1
        + (10 * s3 - 15 * s4 + 6 * s5) * p1,
        dtype=float,
    )


@dataclass(frozen=True)
class TrajectoryPlan:
    """A validated trajectory: knot times from its start [s] and desired bend [rad].

    And the bend's rate [rad/s] and acceleration [rad/s^2] at the knots where the sender
    gave them (then the knots are joined by :func:`hermite` segments).
    """

    t_s: FloatArray
    angle_rad: FloatArray
    name: str = ""
    velocity_rad_s: FloatArray | None = None
    accel_rad_s2: FloatArray | None = None
    _range_rad: tuple[float, float] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        # Curved segments may swing past a knot (by microdegrees on a smooth trajectory); the
        # plan never leaves the range its knots span, which the limits were checked on.
        low, high = float(np.min(self.angle_rad)), float(np.max(self.angle_rad))
        object.__setattr__(self, "_range_rad", (low, high))

    @property
    def duration_s(self) -> float:
        """Time of the last knot [s]."""
        return float(self.t_s[-1])

    @classmethod
    def from_knots(
        cls,
        t_s: npt.ArrayLike,
        angle_rad: npt.ArrayLike,
        limits: TrajectoryLimits,
        control_rate_hz: float,
        name: str = "",
        *,
        velocity_rad_s: npt.ArrayLike | None = None,
        accel_rad_s2: npt.ArrayLike | None = None,
    ) -> TrajectoryPlan:
        """Validate knots as the controller will follow them: resampled on the control clock.

        With velocities the knots are joined by cubic, with accelerations too by quintic
        Hermite segments (:func:`hermite`); accelerations need velocities.

        Raises:
            SignalError: too many points or too long, non-finite, out of range,
                non-increasing time, too fast or too abrupt; the message names the sample and
                the limit.
        """
        t = np.asarray(t_s, dtype=float).ravel()
        a = np.asarray(angle_rad, dtype=float).ravel()
        too_many = limits.size_error(max(t.size, a.size))
        if too_many:
            raise SignalError(too_many)
        if t.size == 0 or t.shape != a.shape:
            raise SignalError(
                f"trajectory needs matching, non-empty times and angles (got {t.size}, {a.size})"
            )
        v = None if velocity_rad_s is None else np.asarray(velocity_rad_s, dtype=float).ravel()
        acc = None if accel_rad_s2 is None else np.asarray(accel_rad_s2, dtype=float).ravel()
        if acc is not None and v is None:
            raise SignalError("trajectory has accelerations without velocities; give both")
        for label, arr in (("velocities", v), ("accelerations", acc)):
            if arr is not None and arr.shape != t.shape:
                raise SignalError(
                    f"trajectory has {arr.size} {label} for {t.size} points; give one per point "
                    "or none"
                )
        named = [("time_from_start", t), ("angle", a)]
        named += [
            (label, arr)
            for label, arr in (("velocity", v), ("acceleration", acc))
            if arr is not None
        ]
        for label, arr in named:
            bad = np.flatnonzero(~np.isfinite(arr))
            if bad.size:
                i = int(bad[0])
                raise SignalError(f"trajectory point {i}: {label} is {arr[i]}; it must be finite")
        # Name the user's own point when a knot is out of range; the grid checks below
        # would name a resampled sample the user never wrote.
        outside = np.flatnonzero((a < limits.min_angle_rad) | (a > limits.max_angle_rad))
        if outside.size:
            i = int(outside[0])
            raise SignalError(
                f"trajectory point {i} (t = {t[i]:g} s) asks for {rad_to_deg(a[i]):.4g} deg, "
                f"outside the allowed [{rad_to_deg(limits.min_angle_rad):.4g}, "
                f"{rad_to_deg(limits.max_angle_rad):.4g}] deg"
            )
        if t[0] < 0.0:
            raise SignalError(f"trajectory point 0 has negative time_from_start {t[0]} s")
        if np.max(t) > limits.max_duration_s:
            i = int(np.argmax(t > limits.max_duration_s))
            raise SignalError(
                f"trajectory point {i} is at time_from_start {t[i]:g} s, over the limit of "
                f"{limits.max_duration_s:g} s (MAX_TRAJECTORY_DURATION_S)"
            )
        if t[0] > 0.0:
            # The plan starts at rest (straight) at t = 0 and moves to the first point.
            t = np.concatenate([[0.0], t])
            a = np.concatenate([[limits.min_angle_rad], a])
            v = None if v is None else np.concatenate([[0.0], v])
            acc = None if acc is None else np.concatenate([[0.0], acc])
        if t.size == 1:
            raise SignalError(
                "trajectory has a single point at time_from_start 0: a step with no time to "
                "move; give the first point a time_from_start > 0"
            )
        # Validate what the controller will actually be asked to follow: the knots
        # interpolated on the control clock for range and rate. Acceleration is judged at a
        # fixed resolution instead: a corner between linear segments is a velocity jump, and
        # on the control grid it would read as jump * rate, so the limit would depend on it.
        if np.all(np.diff(t) > 0.0):
            for rate_hz, check_rate, check_accel in (
                (control_rate_hz, limits.max_rate_rad_s, math.inf),
                (_ACCEL_CHECK_RATE_HZ, math.inf, limits.max_accel_rad_s2),
            ):
                grid = np.append(np.arange(0.0, t[-1], 1.0 / rate_hz), t[-1])
                if grid.size >= 2 and grid[-1] - grid[-2] < 0.5 / rate_hz:
                    grid = np.delete(grid, -2)  # no sliver interval at the end
                check_trajectory(
                    grid,
                    np.clip(hermite(t, a, v, acc, grid), np.min(a), np.max(a)),
                    limits.max_angle_rad,
                    check_rate,
                    check_accel,
                    min_angle_rad=limits.min_angle_rad,
                )
        else:
            i = int(np.flatnonzero(np.diff(t) <= 0.0)[0]) + 1
            raise SignalError(
                f"trajectory time_from_start must increase strictly: point {i} at {t[i]} s "
                f"follows {t[i - 1]} s"
            )
        return cls(t_s=t, angle_rad=a, name=name, velocity_rad_s=v, accel_rad_s2=acc)

    def desired_at(self, elapsed_s: float) -> float:
        """Desired bend [rad] at ``elapsed_s`` from the start (held at the ends)."""
        if self.velocity_rad_s is None:
            return float(np.interp(elapsed_s, self.t_s, self.angle_rad))
        at = np.array([elapsed_s])
        value = hermite(self.t_s, self.angle_rad, self.velocity_rad_s, self.accel_rad_s2, at)[0]
        return min(max(float(value), self._range_rad[0]), self._range_rad[1])


def load_trajectory_file(
    path: Path,
    max_bytes: int = MAX_TRAJECTORY_FILE_BYTES,
    max_points: int = MAX_TRAJECTORY_POINTS,
) -> tuple[FloatArray, FloatArray]:
    """Read trajectory knots from a CSV or YAML file.

    CSV has columns ``t_s`` and ``angle_deg`` (or ``angle_rad``); YAML is a mapping
    ``{t_s: [...], angle_deg: [...]}`` or a list of ``{t_s, angle_deg}``. A file over
    ``max_bytes`` is refused unread, a CSV at its ``max_points + 1``-th row.

    Returns:
        Knot times [s] and angles [rad].
    """
    path = Path(path)
    if not path.is_file():
        raise SignalError(f"trajectory file {path} does not exist")
    # Cheap checks first: the size from the directory entry, the rows while reading, so a
    # file far over the limits is refused before it is parsed (a 10^7-row CSV took 66 s and
    # 1.16 GB to parse whole).
    size_bytes = path.stat().st_size
    if size_bytes > max_bytes:
        raise SignalError(
            f"trajectory file {path} is {size_bytes} bytes, over the limit of {max_bytes} "
            "(MAX_TRAJECTORY_FILE_BYTES); not read"
        )
    rows: dict[str, list[float]]
    if path.suffix.lower() in {".yaml", ".yml"}:
        raw = yaml.safe_load(path.read_text())
        if isinstance(raw, list):
            rows = {k: [float(r[k]) for r in raw] for k in raw[0]} if raw else {}
        elif isinstance(raw, dict):
            rows = {k: [float(v) for v in vals] for k, vals in raw.items()}
        else:
            raise SignalError(f"{path}: expected a mapping or a list of points")
    else:
        with path.open(newline="") as fh:
            reader = csv.DictReader(fh)
            rows = {name: [] for name in reader.fieldnames or []}
            for line_no, row in enumerate(reader, start=2):
                if line_no - 1 > max_points:
                    raise SignalError(
                        f"{path}:{line_no}: more than {max_points} rows, the limit of points "
                        "(MAX_TRAJECTORY_POINTS); not read further"
                    )
                for key, value in row.items():
                    try:
                        rows[key].append(float(value))
                    except (TypeError, ValueError):
                        raise SignalError(
                            f"{path}:{line_no}: column {key!r} holds {value!r}, not a number"
                        ) from None
    if "t_s" not in rows:
        raise SignalError(f"{path}: no 't_s' column/key; found {sorted(rows)}")
    n_points = max((len(v) for v in rows.values()), default=0)
    if n_points > max_points:
        raise SignalError(
            f"{path}: {n_points} points, over the limit of {max_points} (MAX_TRAJECTORY_POINTS)"
        )
    if "angle_rad" in rows:
        angle = np.asarray(rows["angle_rad"], dtype=float)
    elif "angle_deg" in rows:
        angle = deg_to_rad(np.asarray(rows["angle_deg"], dtype=float))
    else:
        raise SignalError(f"{path}: no 'angle_deg' or 'angle_rad' column/key; found {sorted(rows)}")
    return np.asarray(rows["t_s"], dtype=float), angle


def with_lead_in(
    t_s: FloatArray,
    angle_rad: FloatArray,
    approach_s: float = 1.0,
    settle_s: float = 1.0,
    rate_hz: float = 50.0,
) -> tuple[FloatArray, FloatArray, float]:
    """Knots that first bring the catheter from rest to the trajectory's start, then hold.

    A trajectory that does not begin straight (thesis trajectory 2 begins at 8 deg) would
    otherwise open with a step no compensator can follow. The move is the benchmarks' own
    raised cosine (:func:`catheter_models.models.evaluate.lead_in`), so a run on the rig is
    scored like the benchmark. Trajectories that begin at rest are returned unchanged.

    Returns:
        Knot times [s] and angles [rad], and when the trajectory itself starts [s].
    """
    # Imported here, not at the top: evaluate brings in the simulated plant (about 0.7 s even
    # in a running compensator node), which only a lead-in needs.
    from catheter_models.models.evaluate import lead_in

    t = np.asarray(t_s, dtype=float)
    a = np.asarray(angle_rad, dtype=float)
    if a.size == 0 or abs(a[0]) < 1e-6 or t[0] > 0.0:
        return t, a, 0.0  # starts at rest, or already says how to get to its start
    lead = np.concatenate([[0.0], lead_in(float(a[0]), rate_hz, approach_s, settle_s)])[:-1]
    lead_s = lead.size / rate_hz
    return (
        np.concatenate([np.arange(lead.size) / rate_hz, t + lead_s]),
        np.concatenate([lead, a]),
        lead_s,
    )


def preset_knots(name: str, rate_hz: float = 50.0) -> tuple[FloatArray, FloatArray]:
    """Knots of a thesis trajectory preset (sec. 9.3), sampled at ``rate_hz``."""
    spec = get_preset(name)
    if spec.kind != "angle":
        raise SignalError(f"preset {name!r} is a {spec.kind} signal, not an angle trajectory")
    signal = spec.generate(rate_hz)
    return signal.t_s, signal.values_si


_DERIVATIVE_RATE_HZ = 2000.0
"""Rate at which a preset is generated to take its knots' rates and accelerations."""


@dataclass(frozen=True)
class Knots:
    """A trajectory's knots with the bend's rate and acceleration at each.

    For Hermite segments; ``lead_s`` is when the trajectory itself starts after a lead-in.
    """

    t_s: FloatArray
    angle_rad: FloatArray
    velocity_rad_s: FloatArray
    accel_rad_s2: FloatArray
    lead_s: float = 0.0

    def plan(self, limits: TrajectoryLimits, control_rate_hz: float, name: str) -> TrajectoryPlan:
        """The validated plan, joined by quintic Hermite segments."""
        return TrajectoryPlan.from_knots(
            self.t_s,
            self.angle_rad,
            limits,
            control_rate_hz,
            name,
            velocity_rad_s=self.velocity_rad_s,
            accel_rad_s2=self.accel_rad_s2,
        )


def preset_trajectory(name: str, rate_hz: float = 50.0) -> Knots:
    """A thesis trajectory preset (sec. 9.3) knotted at ``rate_hz``, with rate and acceleration.

    Between the knots the plan is then the preset (to microdegrees), not a polyline with a
    kink at every knot: a compensator that reads the plan's acceleration, such as the grey
    box's tip inverse, would see an impulse at every kink.
    """
    t_s, angle_rad = preset_knots(name, rate_hz)
    fine = get_preset(name).generate(_DERIVATIVE_RATE_HZ)
    t_fine = np.asarray(fine.t_s)
    rate = np.gradient(np.asarray(fine.values_si), t_fine)
    accel = np.gradient(rate, t_fine)
    return Knots(t_s, angle_rad, np.interp(t_s, t_fine, rate), np.interp(t_s, t_fine, accel))


def lead_in_knots(
    knots: Knots, approach_s: float = 1.0, settle_s: float = 1.0, rate_hz: float = 50.0
) -> Knots:
    """:func:`with_lead_in` for knots with rates and accelerations.

    The raised cosine's own (analytic) rate and acceleration on the lead-in's knots, zero
    while it holds.
    """
    t, a, lead_s = with_lead_in(knots.t_s, knots.angle_rad, approach_s, settle_s, rate_hz)
    if lead_s == 0.0:
        return knots
    n_lead = t.size - knots.t_s.size
    tl = t[:n_lead]
    moving = tl <= approach_s
    w = np.pi / approach_s
    start = float(knots.angle_rad[0])
    v = np.where(moving, 0.5 * start * w * np.sin(w * tl), 0.0)
    acc = np.where(moving, 0.5 * start * w * w * np.cos(w * tl), 0.0)
    return Knots(
        t,
        a,
        np.concatenate([v, knots.velocity_rad_s]),
        np.concatenate([acc, knots.accel_rad_s2]),
        lead_s,
    )
