"""Feedback on the measured bend beside a feedforward compensator, without ROS.

A feedforward compensator (the static inverse, the IDRDPI, the c-LSTM) is only as good as
its model, and no model is exact on a catheter whose friction changes with the bend of the
shaft, with temperature and with wear. The laser measures the bend at 250 Hz; this module
uses it to correct the command:

    command = feedforward(desired) + kp e + ki integral(e) + kd de/dt,   e = desired - measured

* **Anti-windup.** The command is limited to a window (the pressure clamp, and the slew
  limit around the last command); the integral is corrected by back-calculation toward what
  was actually commanded, so a saturated valve does not leave a wound-up integral behind it.
* **Dead band.** Below its opening pressure the muscle does nothing, so there the integral
  is held: wound down, it would delay the next rise by the time it takes to wind back; wound
  up, it would charge while nothing moves and fire as a spike once the muscle opens. Where
  the bend must rise and the command sits in the dead band, the command goes to the opening
  pressure at once (an inverse of the dead band in the feedback path).
* **Noise and a ringing tip.** The measured bend is low-pass filtered (first order) before
  the error; the derivative, when used, is taken of the filtered measurement, not of the
  set-point, so a set-point step does not kick the valve. Where the tip rings (a lightly
  damped mode at a few hertz), a notch on the measured bend at its frequency keeps the
  feedback from feeding the ringing (:mod:`catheter_models.feedback.tune` decides). The
  set-point passes through the same notch and low-pass before the error, so the error is
  the filtered *error*: a bend that follows the plan reads as following it. Filtering the
  measurement alone delays it (a 4.9 Hz notch of damping 0.5: about 30 ms at 1 Hz), and the
  feedback then pushed a bend the feedforward had right ahead of the plan: the explained
  chain's inverse tracked the Bouc-Wen tip plant's down-chirp to 0.10 deg alone and 0.48
  deg with the PI before; the loop's stability is the same either way (the notch is in the
  loop both times).
* **Authority.** The feedback may move the command at most ``max_correction_pa`` away from
  the feedforward's. A laser that freezes at a plausible value, or reads another bend, then
  cannot drive the catheter to the clamp: the correction stops at the band, and when it has
  pressed against it for ``authority_timeout_s`` the run is cut short
  (:attr:`PIDFeedback.authority_fault`; the node ramps down and says why).
* **Faults.** A non-finite or missing measurement holds the feedback where it is (no
  integration, no proportional kick): feedback never acts on a sample it cannot trust. The
  caller decides when a sensor is stale (the node ramps down).

:class:`ClosedLoop` puts the pieces together for any plant, one sample at a time: ours, a
foreign simulator, or a real rig driven by hand. The compensator node uses
:class:`PIDFeedback` and :func:`~catheter_models.limits.limit_window` inside its control
core, with the same limits.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from catheter_models.contract import FEEDBACK_AUTHORITY_PA, FEEDBACK_AUTHORITY_TIMEOUT_S
from catheter_models.errors import ParameterError
from catheter_models.feedback.seal import SEAL_KEY, check, write_sealed
from catheter_models.limits import limit_window

GAINS_FILE = "feedback.json"
OPENING_ERROR_RAD = math.radians(0.2)
"""A bend this far below the set-point, with the command in the dead band, lifts the command
to the opening pressure: well above the laser's noise (0.05 deg), so a catheter at rest on a
zero set-point is not kicked by it."""
"""Where a model directory keeps its tuned gains (beside the model they were tuned with)."""


@dataclass(frozen=True)
class FeedbackGains:
    """Gains of the feedback on the measured bend, and what they were tuned on.

    Attributes:
        kp_pa_per_rad: Proportional gain [Pa/rad].
        ki_pa_per_rad_s: Integral gain [Pa/(rad s)].
        kd_pa_s_per_rad: Derivative gain [Pa s/rad] (0: a PI).
        measurement_filter_s: Time constant of the first-order low-pass on the measured bend
            [s] (0: none).
        derivative_filter_s: Time constant of the derivative's own low-pass [s].
        tracking_time_s: Back-calculation time of the anti-windup [s] (0: the integral time
            kp / ki, the usual choice).
        opening_pressure_pa: Below this gauge pressure the muscle does nothing [Pa]; the
            integral is held there while the error asks for less bend (0: no deadband).
        notch_frequency_hz: Centre of a notch on the measured bend [Hz] (0: none).
        notch_damping: Damping of the notch's poles (its width; 0.5 is wide).
        max_correction_pa: The farthest the feedback may move the command from the
            feedforward's [Pa] (its authority; a safety limit, so it must be set).
        authority_timeout_s: How long the feedback may press against that limit before the
            run counts as faulty [s].
        tuning: How the gains were found (model, margins), for the record; not used.
    """

    kp_pa_per_rad: float
    ki_pa_per_rad_s: float
    kd_pa_s_per_rad: float = 0.0
    measurement_filter_s: float = 0.0
    derivative_filter_s: float = 0.01
    tracking_time_s: float = 0.0
    opening_pressure_pa: float = 0.0
    notch_frequency_hz: float = 0.0
    notch_damping: float = 0.5
    max_correction_pa: float = FEEDBACK_AUTHORITY_PA
    authority_timeout_s: float = FEEDBACK_AUTHORITY_TIMEOUT_S
    tuning: dict[str, Any] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        for f in fields(self):
            if f.name == "tuning":
                continue
            value = getattr(self, f.name)
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ParameterError(f"feedback {f.name} must be a finite number, got {value!r}")
            if value < 0.0:
                why = (
                    " (a negative gain pushes the bend away from the set-point: a sign error)"
                    if f.name.startswith("k")
                    else ""
                )
                raise ParameterError(f"feedback {f.name} must be >= 0{why}, got {value:g}")
        if self.kd_pa_s_per_rad > 0.0 and self.derivative_filter_s <= 0.0:
            raise ParameterError(
                "feedback derivative_filter_s must be > 0 with a derivative gain "
                "(an unfiltered derivative of the laser is its noise)"
            )
        for name in ("max_correction_pa", "authority_timeout_s"):
            if getattr(self, name) <= 0.0:
                raise ParameterError(f"feedback {name} must be > 0, got {getattr(self, name):g}")
        if self.notch_frequency_hz > 0.0 and self.notch_damping <= 0.0:
            raise ParameterError("feedback notch_damping must be > 0 with a notch")

    @property
    def integral_time_s(self) -> float:
        """The integral time kp / ki [s] (inf for a P or PD)."""
        if self.ki_pa_per_rad_s == 0.0:
            return math.inf
        return self.kp_pa_per_rad / self.ki_pa_per_rad_s

    def save(self, directory: Path) -> Path:
        """Write ``feedback.json``, sealed, into ``directory`` (beside a model); return its path.

        Only gains whose ``tuning`` records what ``catheter-lab tune`` designed load again
        (:mod:`catheter_models.feedback.seal`); gains made by hand are for :class:`ClosedLoop`
        offline, not for a file the compensator runs.
        """
        return write_sealed(asdict(self), Path(directory) / GAINS_FILE)

    @classmethod
    def read(cls, path: Path) -> tuple[Path, dict[str, Any], FeedbackGains]:
        """The file (``path`` or the ``feedback.json`` in it), its content, and its gains.

        Each value is checked on its own here; the seal, the tuned range and the envelope are
        :meth:`load`'s.

        Raises:
            ParameterError: missing file, not JSON, unknown or misspelt keys, or a gain out
                of range.
        """
        path = Path(path)
        if path.is_dir():
            path = path / GAINS_FILE
        try:
            raw = json.loads(path.read_text())
        except FileNotFoundError:
            raise ParameterError(f"no feedback gains at {path}") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise ParameterError(f"{path}: cannot be read ({exc})") from None
        except json.JSONDecodeError as exc:
            raise ParameterError(f"{path}: not JSON ({exc})") from None
        if not isinstance(raw, dict):
            raise ParameterError(f"{path}: expected an object of gains")
        body = {k: v for k, v in raw.items() if k != SEAL_KEY}
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(body) - known)
        if unknown:
            raise ParameterError(
                f"{path}: unknown feedback keys {', '.join(unknown)}; "
                f"known: {', '.join(sorted(known | {SEAL_KEY}))}"
            )
        if not isinstance(body.get("tuning", {}), dict):
            raise ParameterError(f"{path}: tuning must be an object")
        try:
            return path, raw, cls(**body)
        except TypeError as exc:  # a required gain missing
            raise ParameterError(f"{path}: {exc}") from None

    @classmethod
    def load(cls, path: Path) -> FeedbackGains:
        """Read gains from a ``feedback.json`` (or the directory holding one), checked.

        Raises:
            ParameterError: missing file, unknown or misspelt keys, or a gain out of range.
            FeedbackFileError: unsealed, its seal broken, a gain outside its tuned range, or
                an authority or timeout beyond the safety envelope (every problem named).
        """
        path, raw, gains = cls.read(path)
        check(path, raw, asdict(gains))
        return gains


class PIDFeedback:
    """The feedback term: PID on the filtered measured bend, anti-windup, deadband hold.

    Call :meth:`command` once per control tick with the feedforward's pressure and the
    window the command must stay in; it returns the command inside that window.
    """

    def __init__(self, gains: FeedbackGains, rate_hz: float) -> None:
        if not (math.isfinite(rate_hz) and rate_hz > 0.0):
            raise ParameterError(f"feedback rate_hz must be > 0, got {rate_hz}")
        if gains.notch_frequency_hz >= 0.45 * rate_hz:
            raise ParameterError(
                f"feedback notch_frequency_hz {gains.notch_frequency_hz:g} is not below the "
                f"loop's Nyquist frequency ({0.5 * rate_hz:g} Hz at {rate_hz:g} Hz)"
            )
        self.gains = gains
        self._notch = _notch_coefficients(gains.notch_frequency_hz, gains.notch_damping, rate_hz)
        # The bend and the set-point through the same filters: the error is the filtered error.
        self._measured = _BendFilter(self._notch, gains.measurement_filter_s)
        self._reference = _BendFilter(self._notch, gains.measurement_filter_s)
        self.integral_pa = 0.0
        self._derivative_rad_s = 0.0
        self.untrusted_samples = 0
        """Ticks whose measurement was missing or non-finite (feedback held)."""
        self.saturated_ticks = 0
        """Ticks whose wanted command lay outside the window (the anti-windup acted)."""
        self.last_feedback_pa = 0.0
        """The feedback's share of the last command, before limiting [Pa]."""
        self.at_authority_s = 0.0
        """How long the correction has pressed against its authority without a break [s]."""

    def reset(self) -> None:
        """Forget the integral and the filters (a new run from rest)."""
        self.integral_pa = 0.0
        self._derivative_rad_s = 0.0
        self._measured.reset()
        self._reference.reset()
        self.last_feedback_pa = 0.0
        self.at_authority_s = 0.0

    @property
    def authority_fault(self) -> str:
        """Why the run should stop ('' while the feedback is within its authority)."""
        g = self.gains
        if self.at_authority_s < g.authority_timeout_s:
            return ""
        return (
            f"feedback pressed against its +-{g.max_correction_pa / 1e5:g} bar authority for "
            f"{self.at_authority_s:.2f} s: the measured bend does not follow the command "
            "(a frozen, misplaced or misread laser?)"
        )

    def _filter(self, measured_rad: float, dt_s: float) -> tuple[float, float]:
        """The measurement after the low-pass, and its filtered rate [rad/s]."""
        g = self.gains
        previous = self._measured.value
        filtered = self._measured.step(measured_rad, dt_s)
        if previous is None:
            return filtered, 0.0
        if g.kd_pa_s_per_rad > 0.0:
            beta = 1.0 - math.exp(-dt_s / g.derivative_filter_s)
            rate = (filtered - previous) / dt_s
            self._derivative_rad_s += beta * (rate - self._derivative_rad_s)
        return filtered, self._derivative_rad_s

    def command(
        self,
        angle_desired_rad: float,
        angle_measured_rad: float | None,
        feedforward_pa: float,
        *,
        dt_s: float,
        low_pa: float,
        high_pa: float,
        floor_pa: float,
        ceiling_pa: float,
    ) -> float:
        """The command [Pa] for this tick of ``dt_s`` [s].

        ``floor_pa``, ``ceiling_pa``: the pressure clamp. ``low_pa``, ``high_pa``: where the
        command may go this tick (the clamp and the slew limit,
        :func:`~catheter_models.limits.limit_window`).

        The feedback corrects the feedforward as the clamp lets it through (a feedforward
        asking for less than zero is not the feedback's to undo), by at most its authority.
        What the clamp or the authority cut off is given back to the integral
        (back-calculation); while the slew limit holds the command back, the integral does not
        push further against it.
        """
        g = self.gains
        ff_in = min(max(feedforward_pa, floor_pa), ceiling_pa)
        band = g.max_correction_pa
        lo = max(floor_pa, ff_in - band)
        hi = min(ceiling_pa, ff_in + band)
        trusted = (
            angle_measured_rad is not None and math.isfinite(angle_measured_rad) and dt_s > 0.0
        )
        if not trusted:
            # Hold: keep the integral's correction, add nothing new.
            self.untrusted_samples += 1
            self.last_feedback_pa = self.integral_pa
            held = min(max(ff_in + self.integral_pa, lo), hi)
            return min(max(held, low_pa), high_pa)
        assert angle_measured_rad is not None
        filtered, rate = self._filter(angle_measured_rad, dt_s)
        error = self._reference.step(angle_desired_rad, dt_s) - filtered
        proportional = g.kp_pa_per_rad * error
        derivative = -g.kd_pa_s_per_rad * rate
        correction = proportional + self.integral_pa + derivative
        wanted = pi_wanted = ff_in + correction
        if wanted < g.opening_pressure_pa and error > OPENING_ERROR_RAD:
            # The bend must rise but the command is where the muscle does nothing: go to the
            # edge of motion at once instead of charging the integral across the dead band
            # (a charge that fires as a spike once the muscle opens).
            wanted = g.opening_pressure_pa
            correction = wanted - ff_in
        limited = min(max(wanted, lo), hi)
        applied = min(max(limited, low_pa), high_pa)
        if applied != wanted:
            self.saturated_ticks += 1
        # The jump to the opening pressure is not the PI's own asking: what the authority
        # cuts off it is neither wound into the integral nor counted as pressing on the
        # authority. Back-calculated against it, a vented feedforward (the greybox in its
        # deadband) with the opening 0.27 bar beyond the authority wound the integral to
        # -1 bar in 0.1 s, and the next rise came 4 deg late.
        pi_limited = min(max(pi_wanted, lo), hi)
        clamped_only = min(max(pi_wanted, floor_pa), ceiling_pa)
        self.at_authority_s = self.at_authority_s + dt_s if pi_limited != clamped_only else 0.0
        if g.ki_pa_per_rad_s > 0.0:
            push = g.ki_pa_per_rad_s * error
            shut = applied < g.opening_pressure_pa or (
                applied == g.opening_pressure_pa and push < 0.0
            )
            if shut:
                push = 0.0  # the muscle does nothing here: the integral would only charge
            if (applied - limited) * push < 0.0:
                push = 0.0  # the slew limit holds the command back: do not push against it
            # Back-calculation; never faster than a tick, or the correction would overshoot.
            tracking_s = max(g.tracking_time_s or g.integral_time_s, dt_s)
            self.integral_pa += dt_s * (push + (pi_limited - pi_wanted) / tracking_s)
        self.last_feedback_pa = correction
        return applied


Biquad = tuple[float, float, float, float, float]


def _biquad(
    coef: Biquad, state: tuple[float, float] | None, x: float
) -> tuple[float, tuple[float, float]]:
    """One sample through a biquad (transposed direct form II).

    ``state`` None starts it at rest on ``x`` (unit gain at DC).
    """
    b0, b1, b2, a1, a2 = coef
    if state is None:
        state = ((b1 - a1 + b2 - a2) * x, (b2 - a2) * x)
    z1, z2 = state
    y = b0 * x + z1
    return y, (b1 * x - a1 * y + z2, b2 * x - a2 * y)


class _BendFilter:
    """A bend through the notch, then the first-order low-pass, each started at rest.

    The measured bend and the set-point each pass one, so the error is the filtered error,
    not the plan against a delayed bend (module doc).
    """

    def __init__(self, notch: Biquad | None, tau_s: float) -> None:
        self._notch, self._tau_s = notch, tau_s
        self.reset()

    def reset(self) -> None:
        """At rest: the next set-point starts the filters."""
        self._state: tuple[float, float] | None = None
        self.value: float | None = None
        """The last filtered bend (None at rest, before the first)."""

    def step(self, x: float, dt_s: float) -> float:
        """The filtered bend for this tick."""
        if self._notch is not None:
            x, self._state = _biquad(self._notch, self._state, x)
        if self.value is None or self._tau_s <= 0.0:
            self.value = x
        else:
            self.value += (1.0 - math.exp(-dt_s / self._tau_s)) * (x - self.value)
        return self.value


def _notch_coefficients(
    frequency_hz: float, damping: float, rate_hz: float
) -> tuple[float, float, float, float, float] | None:
    """Biquad (b0, b1, b2, a1, a2) of the notch, or None for no notch.

    ``(s^2 + wn^2) / (s^2 + 2 damping wn s + wn^2)``, bilinear, pre-warped so that the notch
    sits exactly at ``frequency_hz``.
    """
    if frequency_hz <= 0.0:
        return None
    wn = 2.0 * math.pi * frequency_hz
    k = wn / math.tan(wn / (2.0 * rate_hz))
    a0 = k * k + 2.0 * damping * wn * k + wn * wn
    b0 = (k * k + wn * wn) / a0
    b1 = 2.0 * (wn * wn - k * k) / a0
    a1 = b1  # numerator and denominator share their middle coefficient
    a2 = (k * k - 2.0 * damping * wn * k + wn * wn) / a0
    return b0, b1, b0, a1, a2


class ClosedLoop:
    """Feedforward plus feedback plus the node's limits, one sample at a time, for any plant.

    ``step(angle_desired_rad, angle_measured_rad) -> pressure_pa``: call it once per sample
    with the set-point and the bend measured since the last command; send the result to the
    valve. A feedforward fitted at a rate must be stepped at that rate (``rate_hz``).

    Args:
        feedforward: A streaming compensator (``step(desired) -> pressure``, ``reset()``,
            ``preview_s``, ``sample_period_s``), or None for feedback alone.
        gains: Feedback gains, or None for feedforward alone.
        rate_hz: The loop's sample rate [Hz].
        min_pressure_pa, max_pressure_pa: The command's clamp, gauge [Pa].
        max_slew_pa_per_s: The command's slew limit [Pa/s].
    """

    def __init__(
        self,
        feedforward: Any | None,
        gains: FeedbackGains | None,
        *,
        rate_hz: float,
        min_pressure_pa: float,
        max_pressure_pa: float,
        max_slew_pa_per_s: float,
    ) -> None:
        if not (math.isfinite(rate_hz) and rate_hz > 0.0):
            raise ParameterError(f"rate_hz must be > 0, got {rate_hz}")
        if not 0.0 <= min_pressure_pa <= max_pressure_pa:
            raise ParameterError(
                "need 0 <= min_pressure_pa <= max_pressure_pa, "
                f"got {min_pressure_pa}, {max_pressure_pa}"
            )
        period = None if feedforward is None else feedforward.sample_period_s
        if period is not None and abs(period * rate_hz - 1.0) > 1e-9:
            raise ParameterError(
                f"the feedforward works at {1.0 / period:g} Hz, the loop at {rate_hz:g} Hz"
            )
        self.feedforward = feedforward
        self.feedback = None if gains is None else PIDFeedback(gains, rate_hz)
        self.dt_s = 1.0 / rate_hz
        self.min_pressure_pa = min_pressure_pa
        self.max_pressure_pa = max_pressure_pa
        self.max_step_pa = max_slew_pa_per_s * self.dt_s
        self._last_pa = 0.0
        self.last_feedforward_pa = 0.0
        self.fault_reason = ""
        """Why the loop ramped down ('' while it runs); cleared by :meth:`reset`."""

    @property
    def preview_s(self) -> float:
        """How far ahead of now the feedforward wants the set-point [s]."""
        return 0.0 if self.feedforward is None else float(self.feedforward.preview_s)

    def reset(self) -> None:
        """Back to rest: the feedforward's state, the feedback's integral, the last command."""
        if self.feedforward is not None:
            self.feedforward.reset()
        if self.feedback is not None:
            self.feedback.reset()
        self._last_pa = 0.0
        self.fault_reason = ""

    def step(
        self,
        angle_desired_rad: float,
        angle_measured_rad: float | None,
        angle_preview_rad: float | None = None,
    ) -> float:
        """The pressure command [Pa] for this sample.

        After a fault (the feedback pressed against its authority too long) the command
        ramps down to zero at the slew limit and stays there until :meth:`reset`, as the
        node's does; :attr:`fault_reason` says why.

        Args:
            angle_desired_rad: The set-point now [rad].
            angle_measured_rad: The latest measured bend [rad] (None or NaN: not trusted).
            angle_preview_rad: The set-point ``preview_s`` ahead, for a feedforward trained
                to see it early (default: the set-point now).
        """
        if self.fault_reason:
            low, high = limit_window(self._last_pa, 0.0, self.max_pressure_pa, self.max_step_pa)
            self._last_pa = min(max(0.0, low), high)
            return self._last_pa
        ahead = angle_desired_rad if angle_preview_rad is None else angle_preview_rad
        ff = 0.0 if self.feedforward is None else float(self.feedforward.step(ahead))
        if not math.isfinite(ff):
            raise ParameterError(f"the feedforward returned {ff} for {ahead:.4f} rad")
        self.last_feedforward_pa = ff
        low, high = limit_window(
            self._last_pa, self.min_pressure_pa, self.max_pressure_pa, self.max_step_pa
        )
        if self.feedback is None:
            command = min(max(ff, low), high)
        else:
            command = self.feedback.command(
                angle_desired_rad,
                angle_measured_rad,
                ff,
                dt_s=self.dt_s,
                low_pa=low,
                high_pa=high,
                floor_pa=self.min_pressure_pa,
                ceiling_pa=self.max_pressure_pa,
            )
            self.fault_reason = self.feedback.authority_fault
        self._last_pa = command
        return command
