"""Is a bag's data plausible? Values against the contract, stamps against each other and the log.

``load_bag`` runs :func:`check_streams` on every bag it reads, before it drops non-finite
samples or sorts stamps, so nothing it would hide goes unsaid. Each finding names the topic,
the check, how many samples and where the first one is (log time since the bag's start), and
is either a refusal (the bag is refused unless a person accepts it knowingly,
``--accept-implausible``) or a warning (the data stays usable and the finding is said).

The rules, check by check:

* **range** (refuse): a pressure outside ``[-PRESSURE_NOISE_MARGIN_PA,
  PRESSURE_LIMIT_HARD_PA + PRESSURE_NOISE_MARGIN_PA]`` gauge, a bend outside the joint's limits
  (``THESIS_GEOMETRY.max_angle_rad``, the URDF's ``bend`` joint: eq. 3.3 cannot give more). No
  rig can have produced such a value, so a model would learn a unit slip or garbage.
* **units** (refuse): a recognisable unit mistake, named. Pressures whose largest magnitude is
  above zero but at most ``PRESSURE_LIMIT_HARD_PA`` / 1e5 "Pa" are bar stored as Pa (1e5 times
  too small: every real pressure transmitter reads more than 6 Pa of noise, and a muscle needs
  tenths of a bar to move). Out-of-range bends beyond a half turn that would all lie within the
  joint's limits if read as degrees are degrees stored as radians; out-of-range pressures near
  minus the ambient pressure are a gauge value stored in ``FluidPressure``'s absolute field,
  and those whose absolute value is a few "Pa" are absolute pressure in bar.
* **non-finite** (warn up to ``NON_FINITE_REFUSE_SHARE`` of a topic's samples, refuse above):
  NaN or infinite samples are dropped and the resampling interpolates across them; a few are a
  sensor's glitch, a large share means the stream is mostly made up.
* **stamps not increasing** (refuse): a header stamp earlier than the one before it in the
  file. One publisher per topic stamps in order and DDS delivers in order, so this is a clock
  stepped back, streams spliced or reversed; sorting would silently invent a time base.
* **repeated stamps** (warn up to ``REPEATED_STAMP_REFUSE_SHARE`` of a topic's samples, refuse
  above): samples claiming an instant another sample of the topic already claims; which value
  held then is unknown. A few happen on real drivers (the laser driver stamps its first samples,
  before its time base settles, with one stamp: 9 to 45 of 7,000 in the emulated rig's bags);
  a large share is a broken time base.
* **starts after the motion** (warn): a sensor stream (``tip/angle``, ``pressure/measured``)
  whose first sample comes after ``pressure/command`` left rest; the bag begins mid-motion.
* **stamps vs log time** (refuse when the stamps' span and the log times' span differ by more
  than ``STAMP_RATE_TOLERANCE`` of the log span and ``STAMP_LOG_TOLERANCE_S``: the stamps run
  on another clock rate or unit; warn when single samples were logged more than
  ``STAMP_LOG_TOLERANCE_S`` away from the topic's usual stamp-to-log offset: late or early
  stamps, whose values are still placed by their stamps).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Final, Literal

import numpy as np
import numpy.typing as npt

from catheter_models.contract import (
    ANGLE_DESIRED,
    PRESSURE_COMMAND,
    PRESSURE_LIMIT_HARD_PA,
    PRESSURE_MEASURED,
    TIP_ANGLE,
)
from catheter_models.errors import BagError
from catheter_models.geometry import THESIS_GEOMETRY
from catheter_models.units import AMBIENT_PRESSURE_PA, NS_PER_S, PA_PER_BAR, rad_to_deg

ACCEPT_FLAG: Final = "--accept-implausible"
"""The command-line flag that lets a person go on with a bag this check refuses."""

PRESSURE_NOISE_MARGIN_PA: Final = 0.5 * PA_PER_BAR
"""How far beyond [0, ``PRESSURE_LIMIT_HARD_PA``] a measured pressure may read (0.5 bar): five
standard deviations of the noisiest transmitter the simulated rig accepts (``pressure_noise_pa``
up to 0.1 bar), twenty times a 0-10 bar transmitter's 0.25 % accuracy. The check is after unit
slips and garbage (factors of 10^5, 300 bar), not calibration."""
NON_FINITE_REFUSE_SHARE: Final = 0.05
"""Above this share of a topic's samples non-finite, the bag is refused (at most, warned)."""
REPEATED_STAMP_REFUSE_SHARE: Final = 0.05
"""Above this share of a topic's samples with a repeated stamp, the bag is refused."""
STAMP_LOG_TOLERANCE_S: Final = 1.0
"""A sample logged this much later or earlier than its topic's usual stamp-to-log offset is
out of step [s]: ten times the command watchdog, far beyond DDS delivery on a loaded host."""
STAMP_RATE_TOLERANCE: Final = 0.01
"""Share by which a topic's stamp span may differ from its log span (clock rates agree to ppm)."""

BEND_LIMIT_RAD: Final = THESIS_GEOMETRY.max_angle_rad
"""The ``bend`` joint's limit [rad] (the URDF's, checked equal by tests/catheter_control)."""

_PRESSURES: Final = frozenset({PRESSURE_COMMAND.name, PRESSURE_MEASURED.name})
_BENDS: Final = frozenset({TIP_ANGLE.name, ANGLE_DESIRED.name})

Severity = Literal["refuse", "warn"]
FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


@dataclass(frozen=True)
class Finding:
    """One thing wrong with one topic's data.

    Attributes:
        topic: The topic in the bag.
        check: Which check: ``range``, ``units``, ``non-finite``, ``stamps not increasing``,
            ``repeated stamps``, ``stamps vs log time``.
        severity: ``refuse`` (the bag is refused unless accepted) or ``warn``.
        count: Offending samples.
        total: Samples on the topic.
        first_s: Log time of the first offending sample [s since the bag's start].
        detail: What was seen, for a person.
        unit: What ``count`` and ``total`` count (``samples``; ``chunks`` or ``topics`` for
            what the loader finds about the file itself).
    """

    topic: str
    check: str
    severity: Severity
    count: int
    total: int
    first_s: float | None
    detail: str
    unit: str = "samples"

    def describe(self) -> str:
        """One line: topic, check, counts, first offending time, what was seen."""
        where = "" if self.first_s is None else f", first at {self.first_s:.3f} s"
        return (
            f"{self.topic}: {self.check}: {self.count} of {self.total} {self.unit}{where}; "
            f"{self.detail}"
        )

    def to_dict(self) -> dict[str, Any]:
        """For a model's manifest or a JSON report."""
        return {
            "topic": self.topic,
            "check": self.check,
            "severity": self.severity,
            "count": self.count,
            "total": self.total,
            "first_s": self.first_s,
            "detail": self.detail,
            "unit": self.unit,
        }


@dataclass(frozen=True)
class PlausibilityReport:
    """Every finding of one bag (empty: plausible)."""

    findings: tuple[Finding, ...] = ()

    @property
    def refusals(self) -> tuple[Finding, ...]:
        """Findings that refuse the bag unless a person accepts it."""
        return tuple(f for f in self.findings if f.severity == "refuse")

    @property
    def warnings(self) -> tuple[Finding, ...]:
        """Findings that leave the data usable."""
        return tuple(f for f in self.findings if f.severity == "warn")

    def lines(self) -> list[str]:
        """One line per finding, refusals first, each marked REFUSE or warn."""
        return [f"REFUSE {f.describe()}" for f in self.refusals] + [
            f"warn   {f.describe()}" for f in self.warnings
        ]


class PlausibilityWarning(UserWarning):
    """A finding on a bag that is used anyway: a warning, or a refusal a person accepted.

    Attributes:
        bag: The bag.
        finding: The finding.
        accepted: True for a refusing finding that a person accepted (``--accept-implausible``).
    """

    def __init__(self, bag: object, finding: Finding, *, accepted: bool = False) -> None:
        """Say the bag and the finding; an accepted refusal says so."""
        self.bag = bag
        self.finding = finding
        self.accepted = accepted
        said = "implausible, accepted knowingly" if accepted else "used with a warning"
        super().__init__(f"{bag} ({said}): {finding.describe()}")


class ImplausibleBagError(BagError):
    """A bag's data fails the plausibility check; the message names every refusing finding."""

    def __init__(self, bag: object, report: PlausibilityReport) -> None:
        """Name the bag, each refusing finding, and how to go on knowingly."""
        self.report = report
        lines = "; ".join(f.describe() for f in report.refusals)
        super().__init__(
            f"bag {bag} holds implausible data, refused: {lines}. Fix or re-record it, or go on "
            f"knowingly with {ACCEPT_FLAG} (the findings are then printed and recorded)"
        )


@dataclass(frozen=True)
class StreamSamples:
    """One topic's samples as the file holds them: log order, nothing dropped or sorted.

    Attributes:
        name: Contract name (``pressure/command``, ``tip/angle``, ...).
        topic: Topic in the bag.
        stamps_ns: Header stamps [ns since the epoch].
        log_ns: Log (receive) times [ns since the epoch].
        values: Values in SI (gauge Pa, rad, m), non-finite ones included.
    """

    name: str
    topic: str
    stamps_ns: IntArray
    log_ns: IntArray
    values: FloatArray


def check_streams(
    streams: Sequence[StreamSamples],
    start_ns: int,
    ambient_pa: float = AMBIENT_PRESSURE_PA,
) -> PlausibilityReport:
    """Every finding on these streams (see the module docstring for the rules).

    Args:
        streams: Each topic's samples in log order.
        start_ns: The bag's start [ns]; first offending times count from here.
        ambient_pa: The ambient pressure subtracted to get gauge (to name absolute/gauge slips).
    """
    findings: list[Finding] = []
    for stream in streams:
        if stream.values.size == 0:
            continue
        findings += _check_values(stream, start_ns, ambient_pa)
        findings += _check_stamps(stream, start_ns)
    findings += _check_start_at_rest(streams, start_ns)
    return PlausibilityReport(tuple(findings))


_AT_REST_PA: Final = 1.0e3
"""A pressure command above this has left rest [Pa gauge]."""
_SENSORS: Final = ("tip/angle", "pressure/measured")


def _check_start_at_rest(streams: Sequence[StreamSamples], start_ns: int) -> list[Finding]:
    """Sensor streams that begin only after the command left rest: the bag starts mid-motion.

    Every model is run from rest at a bag's start: a recorder that heard the laser 2.2 s into
    a live excitation taught the lab a wrong rest (0.51 deg against 0.11).
    """
    by_name = {s.name: s for s in streams if s.values.size}
    command = by_name.get("pressure/command")
    if command is None:
        return []
    moving = np.flatnonzero(np.nan_to_num(command.values) > _AT_REST_PA)
    if moving.size == 0:
        return []
    left_rest_ns = int(command.stamps_ns[moving[0]])
    out = []
    for name in _SENSORS:
        stream = by_name.get(name)
        if stream is None or int(stream.stamps_ns[0]) <= left_rest_ns:
            continue
        late_s = (int(stream.stamps_ns[0]) - left_rest_ns) / NS_PER_S
        out.append(
            Finding(
                topic=stream.topic,
                check="starts after the motion",
                severity="warn",
                count=1,
                total=int(stream.values.size),
                first_s=float(stream.log_ns[0] - start_ns) / NS_PER_S,
                detail=(
                    f"its first sample is {late_s:.2f} s after pressure/command left rest: the "
                    "bag does not start at rest, and models run from rest at its start (the "
                    "recorder heard the sensor late?)"
                ),
                unit="first samples",
            )
        )
    return out


def _first_s(stream: StreamSamples, mask: npt.NDArray[np.bool_], start_ns: int) -> float | None:
    index = np.flatnonzero(mask)
    if index.size == 0:
        return None
    return float(stream.log_ns[index[0]] - start_ns) / NS_PER_S


def _finding(
    stream: StreamSamples,
    check: str,
    severity: Severity,
    *,
    mask: npt.NDArray[np.bool_],
    start_ns: int,
    detail: str,
) -> Finding:
    return Finding(
        topic=stream.topic,
        check=check,
        severity=severity,
        count=int(np.count_nonzero(mask)),
        total=int(stream.values.size),
        first_s=_first_s(stream, mask, start_ns),
        detail=detail,
    )


def _check_values(stream: StreamSamples, start_ns: int, ambient_pa: float) -> list[Finding]:
    out: list[Finding] = []
    values = stream.values
    finite = np.isfinite(values)
    non_finite = ~finite
    if non_finite.any():
        share = float(np.count_nonzero(non_finite)) / values.size
        refuse = share > NON_FINITE_REFUSE_SHARE
        detail = (
            f"{share:.1%} of the samples are NaN or infinite (more than "
            f"{NON_FINITE_REFUSE_SHARE:.0%}: too much of the stream would be interpolated)"
            if refuse
            else f"{share:.1%} NaN or infinite, dropped; the resampling interpolates across them"
        )
        out.append(
            _finding(
                stream,
                "non-finite",
                "refuse" if refuse else "warn",
                mask=non_finite,
                start_ns=start_ns,
                detail=detail,
            )
        )
    if not finite.any():
        return out
    good = values[finite]
    if stream.name in _PRESSURES:
        out += _check_pressure(stream, finite, good, start_ns, ambient_pa)
    elif stream.name in _BENDS:
        out += _check_bend(stream, finite, good, start_ns)
    return out


def _check_pressure(
    stream: StreamSamples,
    finite: npt.NDArray[np.bool_],
    good: FloatArray,
    start_ns: int,
    ambient_pa: float,
) -> list[Finding]:
    values = stream.values
    low_pa, high_pa = -PRESSURE_NOISE_MARGIN_PA, PRESSURE_LIMIT_HARD_PA + PRESSURE_NOISE_MARGIN_PA
    with np.errstate(invalid="ignore"):
        outside = finite & ((values < low_pa) | (values > high_pa))
    largest_pa = float(np.max(np.abs(good)))
    if outside.any():
        worst = float(good[np.argmax(np.abs(good))])
        detail = (
            f"pressure outside [{low_pa:.6g}, {high_pa:.6g}] Pa gauge (the hard bound "
            f"{PRESSURE_LIMIT_HARD_PA:.6g} Pa with {PRESSURE_NOISE_MARGIN_PA:.6g} Pa of "
            f"transmitter noise), extreme {worst:.6g} Pa ({worst / PA_PER_BAR:.4g} bar)"
        )
        absolute = good + ambient_pa
        if np.all(np.abs(absolute) <= (PRESSURE_LIMIT_HARD_PA + ambient_pa) / PA_PER_BAR):
            detail += (
                "; the absolute values are at most "
                f"{float(np.max(np.abs(absolute))):.4g} 'Pa': absolute pressure stored in bar"
            )
        elif np.all((good >= low_pa - ambient_pa) & (good <= high_pa - ambient_pa)):
            detail += (
                f"; the values sit near -{ambient_pa:.6g} Pa: gauge pressure stored in "
                "FluidPressure's absolute field"
            )
        return [_finding(stream, "range", "refuse", mask=outside, start_ns=start_ns, detail=detail)]
    if 0.0 < largest_pa <= PRESSURE_LIMIT_HARD_PA / PA_PER_BAR:
        nonzero = finite & (values != 0.0)
        detail = (
            f"the largest |pressure| is {largest_pa:.4g} Pa: bar stored as Pa (values "
            f"{PA_PER_BAR:.0e} times too small; read as bar it would be {largest_pa:.4g} bar)"
        )
        return [_finding(stream, "units", "refuse", mask=nonzero, start_ns=start_ns, detail=detail)]
    return []


def _check_bend(
    stream: StreamSamples, finite: npt.NDArray[np.bool_], good: FloatArray, start_ns: int
) -> list[Finding]:
    values = stream.values
    with np.errstate(invalid="ignore"):
        outside = finite & (np.abs(values) > BEND_LIMIT_RAD)
    if not outside.any():
        return []
    worst = float(good[np.argmax(np.abs(good))])
    detail = (
        f"bend beyond the joint's limits +/-{BEND_LIMIT_RAD:.4g} rad "
        f"({float(rad_to_deg(BEND_LIMIT_RAD)):.1f} deg), extreme {worst:.4g} rad "
        f"({float(rad_to_deg(worst)):.0f} deg)"
    )
    # Beyond a half turn no bend in radians makes sense; within the limits read as degrees,
    # the values are degrees.
    if math.pi < abs(worst) <= float(rad_to_deg(BEND_LIMIT_RAD)):
        detail += (
            f"; read as degrees every value is within the limits (extreme {worst:.4g} deg): "
            "degrees stored as radians"
        )
        return [_finding(stream, "units", "refuse", mask=outside, start_ns=start_ns, detail=detail)]
    return [_finding(stream, "range", "refuse", mask=outside, start_ns=start_ns, detail=detail)]


def _check_stamps(stream: StreamSamples, start_ns: int) -> list[Finding]:
    out: list[Finding] = []
    stamps = stream.stamps_ns
    if stamps.size < 2:
        return out
    step = np.diff(stamps)
    back = np.concatenate(([False], step < 0))
    if back.any():
        i = int(np.flatnonzero(back)[0])
        back_s = float(stamps[i - 1] - stamps[i]) / NS_PER_S
        out.append(
            _finding(
                stream,
                "stamps not increasing",
                "refuse",
                mask=back,
                start_ns=start_ns,
                detail=f"a header stamp is earlier than the one before it in the file (first by "
                f"{back_s:.6g} s); the time base cannot be trusted, and sorting would hide it",
            )
        )
    order = np.argsort(stamps, kind="stable")
    repeated_sorted = np.concatenate(([False], np.diff(stamps[order]) == 0))
    repeated = np.zeros(stamps.size, dtype=bool)
    repeated[order] = repeated_sorted
    if repeated.any():
        share = float(np.count_nonzero(repeated)) / stamps.size
        out.append(
            _finding(
                stream,
                "repeated stamps",
                "refuse" if share > REPEATED_STAMP_REFUSE_SHARE else "warn",
                mask=repeated,
                start_ns=start_ns,
                detail=f"{share:.1%} of the samples carry a header stamp another sample of the "
                "topic already has; which value held at that instant is unknown"
                + (
                    f" (more than {REPEATED_STAMP_REFUSE_SHARE:.0%}: the time base is broken)"
                    if share > REPEATED_STAMP_REFUSE_SHARE
                    else "; both are kept in file order"
                ),
            )
        )
    if not back.any():
        # Stamps that go back already fail; their span says nothing more about the clock.
        out += _check_log_step(stream, start_ns)
    return out


def _check_log_step(stream: StreamSamples, start_ns: int) -> list[Finding]:
    stamps, logs = stream.stamps_ns, stream.log_ns
    log_span_s = float(logs.max() - logs.min()) / NS_PER_S
    stamp_span_s = float(stamps.max() - stamps.min()) / NS_PER_S
    allowed_s = max(STAMP_LOG_TOLERANCE_S, STAMP_RATE_TOLERANCE * log_span_s)
    if abs(stamp_span_s - log_span_s) > allowed_s:
        everything = np.ones(stamps.size, dtype=bool)
        return [
            _finding(
                stream,
                "stamps vs log time",
                "refuse",
                mask=everything,
                start_ns=start_ns,
                detail=f"the header stamps span {stamp_span_s:.6g} s but the messages were logged "
                f"over {log_span_s:.6g} s: the stamps run on another clock rate or unit",
            )
        ]
    offset_ns = (logs - stamps).astype(np.float64)
    deviation_s = (offset_ns - float(np.median(offset_ns))) / NS_PER_S
    astray = np.abs(deviation_s) > STAMP_LOG_TOLERANCE_S
    if not astray.any():
        return []
    return [
        _finding(
            stream,
            "stamps vs log time",
            "warn",
            mask=astray,
            start_ns=start_ns,
            detail=f"logged up to {float(np.max(np.abs(deviation_s))):.3g} s away from the topic's "
            f"usual stamp-to-log offset (more than {STAMP_LOG_TOLERANCE_S:g} s); the values are "
            "placed by their stamps",
        )
    ]
