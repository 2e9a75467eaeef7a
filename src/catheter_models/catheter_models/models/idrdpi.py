"""The inverse DRDPI (thesis ch. 9): desired bend -> valve pressure, a feedforward compensator.

Every IDRDPI is one DRDPI-structure operator chain mapping angle [deg] to pressure [bar],
run by the shared kernels (:func:`catheter_models.hysteresis.operators.chain_run`); its
:meth:`IDRDPI.stream` is what the compensator node steps. How the chain's 12 parameters
(Table 5.1's) are found is the ``method``:

``"analytic"`` (sec. 9.1.1)
    Fit a forward DRDPI (pressure -> angle) on the recordings and invert it with eqs.
    9.2-9.11: ``E⁻¹ = y⁻¹ ∘ Z⁻¹``, the inverse deadband (eqs. 9.7-9.11) then the inverse PI
    (thresholds 9.3-9.4, weights 9.6). The inverse's thresholds need the pressure rate
    (eq. 5.6), which the inverse does not know before it has computed the pressure; it uses
    the rate of its own PI-stage input ``v = Z⁻¹(desired)`` divided by the PI's major-loop
    slope ``a0 + sum a_i`` (see :func:`inverse.invert_chain`). That is causal, the same in
    batch and stream, and exact for slow signals (the rate term vanishes).
``"gpi"`` (sec. 9.2, the thesis's optimisation route)
    Group the recordings by excitation frequency (by the ``_f<Hz>`` tag in their names when
    every one has it, else by the dominant frequency of the pressure; ``grouping``), fit one
    GPI per group (eqs. 9.12-9.16), invert each (eqs. 9.17-9.21), drive each inverse with
    desired-angle descending sines at its frequency (the shapes of eqs. 4.1/4.2) to make
    ``virtual_samples`` of virtual (angle -> pressure) data, and identify the IDRDPI's
    parameters on it.
``"direct"``
    Identify the IDRDPI's parameters on the measured data, angle in, pressure out. The
    measured angle is low-passed without phase shift (``smooth_hz``) first: at run time the
    input is a clean desired trajectory, and laser noise in the rate term would bias β.

For ``gpi`` and ``direct`` the ``structure`` says what the 12 parameters describe:

``"inverse"`` (default)
    The chain is ``E_θ⁻¹``, the analytic inverse of a DRDPI with parameters θ (in forward
    units, bar -> deg): the form the thesis identifies in step 3 of sec. 9.2 ("all functions
    of the IDRDPI model are introduced in subsection 9.1.1"). Every θ in the default box is
    well-posed, and the deadband's inverse (a jump to the opening pressure) comes for free.
``"drdpi"``
    The chain is the plain DRDPI structure ``Z(PI(angle))`` with angle [deg] in and pressure
    [bar] out. To represent an inverse it needs clockwise loops (play weights < 0) and a
    concave deadband sum (g_j < 0 after a steep g0); its default box
    (:data:`DRDPI_STRUCTURE_BOUNDS`) allows both, and the search rejects candidates that are
    not increasing.

Pressure out is finite for every finite input (each stage is a finite sum of finite terms);
clamping to the valve's range is the compensator node's job.
"""

from __future__ import annotations

import json
import math
import re
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, Final, Literal, get_args

import numpy as np
import numpy.typing as npt
from scipy.signal import butter, sosfiltfilt

from catheter_models.contract import SENSOR_RATE_HZ
from catheter_models.errors import ParameterError
from catheter_models.model_dir import Manifest
from catheter_models.models.base import (
    DataRequirement,
    FitReport,
    FloatArray,
    InsufficientDataError,
    Model,
    ModelError,
    NotFittedError,
    Recording,
    as_input,
    paired_ahead,
    read_ahead,
    saved_rate_hz,
)
from catheter_models.models.drdpi import (
    DEFAULT_BOUNDS,
    DRDPI,
    DRDPI_PARAMS_FILE,
    FORWARD_UNITS,
    PARAMS_FILE,
    SEARCH_NAMES,
    ChainStream,
    DRDPIParams,
    DRDPIProblem,
    chain_coefficients,
    identify_chain,
    run_chain,
)
from catheter_models.models.gpi import GPI, GPIParams
from catheter_models.models.identify import Budget, ParameterBounds
from catheter_models.units import bar_to_pa, deg_to_rad, pa_to_bar, rad_to_deg

if TYPE_CHECKING:
    from typing import Self  # 3.11+; annotations only, so 3.10 imports the module

Method = Literal["analytic", "gpi", "direct"]
Structure = Literal["inverse", "drdpi"]
Grouping = Literal["auto", "name", "frequency"]
METHODS: Final = get_args(Method)
STRUCTURES: Final = get_args(Structure)
GROUPINGS: Final = get_args(Grouping)

DRDPI_STRUCTURE_UNITS: Final[Mapping[str, str]] = {
    "alpha0": "1",
    "alpha1": "bar/deg",
    "alpha2": "bar/deg",
    "beta0": "1",
    "beta1": "1",
    "beta2": "1",
    "dp": "deg",
    "dn": "deg",
    "zeta": "deg",
    "beta": "s",
    "a0": "1",
    "g0": "bar/deg",
}
"""Units of the parameters when the chain is the plain DRDPI structure, angle in, pressure
out; y is in degrees because a0 is held at 1."""

DRDPI_STRUCTURE_BOUNDS: Final[Mapping[str, tuple[float, float]]] = {
    "a1": (-1.0, 0.0),
    "g1": (-5.0, 0.0),
    "gm1": (0.0, 0.0),
    "beta0": (-0.5, 6.0),
    "beta1": (-0.5, 6.0),
    "beta2": (0.0, 0.0),
    "dp": (0.05, 10.0),
    "dn": (10.0, 10.0),
    "zeta": (0.05, 5.0),
    "beta": (0.0, 0.2),
    "a0": (1.0, 1.0),
    "g0": (1e-3, 10.0),
}
"""Search box of the plain DRDPI structure, angle [deg] -> pressure [bar], over
``drdpi.SEARCH_NAMES``. a1 <= 0: an inverse's loops run clockwise. g1 <= 0: the inverse
deadband is concave (a steep rise to the opening pressure, then the plant's inverse slope).
a0 = 1 holds y's scale (y in degrees), and dp, the knee, is free: it sits near zero angle."""

_NAME_FREQUENCY = re.compile(r"_f(\d+(?:\.\d+)?)(?:_|$)")
_MIN_FREQUENCY_HZ = 0.05
"""Spectral peaks below this are the decaying envelope, not the excitation."""

IDRDPI_META_FILE: Final = "idrdpi.json"
IDRDPI_META_FORMAT: Final = "catheter_models.idrdpi/1"

MAX_PREVIEW_S: Final = 0.5
"""Longest dead time the IDRDPI reads ahead [s]: a loop slower than this is not a catheter's."""


def _led(recording: Recording, lead: int) -> Recording:
    """``recording`` with each pressure paired with the bend ``lead`` samples later."""
    if recording.pressure_pa.size <= lead + 1:
        raise InsufficientDataError(
            f"recording {recording.name!r} has {recording.pressure_pa.size} samples, too few "
            f"for a preview of {lead}"
        )
    angle_rad, pressure_pa = paired_ahead(recording.angle_rad, recording.pressure_pa, lead)
    return Recording(
        name=recording.name,
        rate_hz=recording.rate_hz,
        pressure_pa=pressure_pa,
        angle_rad=angle_rad,
        source=recording.source,
        sha256=recording.sha256,
        measurement_age_s=recording.measurement_age_s,
    )


@dataclass(frozen=True, eq=False)
class FrequencyGroup:
    """Recordings excited at (about) one frequency.

    Attributes:
        frequency_hz: The group's frequency [Hz] (tag, or mean of the estimates).
        recordings: The recordings in it.
    """

    frequency_hz: float
    recordings: tuple[Recording, ...]


def dominant_frequency_hz(values: npt.ArrayLike, rate_hz: float) -> float:
    """Frequency [Hz] of the largest spectral peak above 0.05 Hz (mean removed, zero-padded).

    Raises:
        ParameterError: The signal is too short or has no peak above 0.05 Hz.
    """
    x = np.asarray(values, dtype=np.float64)
    if x.size < 16:
        raise ParameterError(f"{x.size} samples are too few to estimate a frequency (need 16)")
    x = (x - x.mean()) * np.hanning(x.size)
    n_fft = 1 << math.ceil(math.log2(8 * x.size))
    spectrum = np.abs(np.fft.rfft(x, n_fft))
    freqs = np.fft.rfftfreq(n_fft, 1.0 / rate_hz)
    usable = freqs >= _MIN_FREQUENCY_HZ
    if not np.any(spectrum[usable] > 0.0):
        raise ParameterError("signal has no spectral peak above 0.05 Hz: is it constant?")
    return float(freqs[usable][int(np.argmax(spectrum[usable]))])


def frequency_tag_hz(name: str) -> float | None:
    """The ``_f<Hz>`` tag of a recording's name (``train_zero_f0.2`` -> 0.2), or None."""
    match = _NAME_FREQUENCY.search(name)
    return float(match.group(1)) if match else None


def group_by_frequency(
    recordings: Sequence[Recording], grouping: Grouping = "auto", tolerance: float = 0.2
) -> list[FrequencyGroup]:
    """Split recordings by excitation frequency, lowest first.

    Args:
        recordings: The training recordings.
        grouping: ``name`` uses the ``_f<Hz>`` tags (all must have one); ``frequency``
            estimates the dominant frequency of each pressure signal; ``auto`` uses the tags
            when every recording has one, else the estimates.
        tolerance: Frequencies within this relative distance of a group's lowest join it.

    Raises:
        ParameterError: ``name`` grouping with an untagged recording, or a bad setting.
    """
    if grouping not in GROUPINGS:
        raise ParameterError(f"grouping = {grouping!r} must be one of {GROUPINGS}")
    if not 0.0 < tolerance < 1.0:
        raise ParameterError(f"frequency tolerance = {tolerance!r} must be in (0, 1)")
    tags = [frequency_tag_hz(r.name) for r in recordings]
    use_tags = grouping == "name" or (grouping == "auto" and all(t is not None for t in tags))
    if use_tags:
        missing = [r.name for r, t in zip(recordings, tags, strict=True) if t is None]
        if missing:
            raise ParameterError(
                f"grouping by name needs an '_f<Hz>' tag in every recording name; "
                f"{missing} have none (use grouping='frequency')"
            )
        freqs = [float(t) for t in tags if t is not None]
    else:
        freqs = [dominant_frequency_hz(r.pressure_pa, r.rate_hz) for r in recordings]
    order = np.argsort(freqs, kind="stable")
    groups: list[tuple[list[float], list[Recording]]] = []
    for i in order:
        f = freqs[int(i)]
        if groups and abs(f - groups[-1][0][0]) <= tolerance * groups[-1][0][0]:
            groups[-1][0].append(f)
            groups[-1][1].append(recordings[int(i)])
        else:
            groups.append(([f], [recordings[int(i)]]))
    return [FrequencyGroup(float(np.mean(fs)), tuple(rs)) for fs, rs in groups]


def virtual_angle_signals(
    frequency_hz: float,
    peak_deg: float,
    n_samples: int,
    rate_hz: float,
    decays_per_s: Sequence[float] = (0.05, 0.15),
) -> list[FloatArray]:
    """Desired-angle descending sines at one frequency, to drive an inverse GPI.

    The shapes of eqs. 4.1 (zero baseline) and 4.2 (non-zero baseline) in angle, amplitude
    ``peak_deg / 2`` so both start at rest and peak at ``peak_deg``, one per decay, sharing
    ``n_samples`` evenly.

    Returns:
        Angle signals [deg], each from 0.
    """
    per_signal = max(2, n_samples // (2 * len(decays_per_s)))
    t = np.arange(per_signal) / rate_hz
    amp = 0.5 * peak_deg
    phase = 2.0 * math.pi * frequency_hz * t - 0.5 * math.pi
    out: list[FloatArray] = []
    for tau in decays_per_s:
        env = amp * np.exp(-tau * t)
        out.append(env * (np.sin(phase) + 1.0))
        out.append(env * np.sin(phase) + amp)
    return out


def smooth(values: FloatArray, rate_hz: float, cutoff_hz: float) -> FloatArray:
    """Zero-phase 2nd-order Butterworth low-pass (training data only; 0 = unchanged).

    Raises:
        ParameterError: The cutoff is not below the Nyquist frequency.
    """
    if cutoff_hz == 0.0 or values.size < 16:
        return values
    if cutoff_hz >= 0.5 * rate_hz:
        raise ParameterError(
            f"smooth_hz = {cutoff_hz:g} must be below half the sample rate ({0.5 * rate_hz:g} Hz)"
        )
    sos = butter(2, cutoff_hz, fs=rate_hz, output="sos")
    out: FloatArray = sosfiltfilt(sos, values)
    return out


class IDRDPI(Model):
    """Inverse DRDPI: desired bend [rad] -> valve pressure [Pa], streamed as a compensator.

    Args:
        method: ``analytic``, ``gpi`` or ``direct`` (module docstring).
        structure: ``inverse`` (E_θ⁻¹, default) or ``drdpi`` (Z(PI(angle))); ``analytic``
            is always ``inverse``.
        n_play: N play operators of the chain.
        n_deadband: k; 2k + 1 deadband operators.
        rate_filter_s: Time constant of the rate estimate's low-pass [s].
        bounds: Search box over ``drdpi.SEARCH_NAMES`` (missing names take the default box
            of the structure: ``drdpi.DEFAULT_BOUNDS`` or :data:`DRDPI_STRUCTURE_BOUNDS`).
        budget: Effort of the DRDPI/IDRDPI identification (``Budget`` or mapping).
        seed: Seed of every search.
        grouping: How ``gpi`` splits recordings by frequency (:func:`group_by_frequency`).
        frequency_tolerance: Relative width of a frequency group.
        gpi_n_play: Play operators of each GPI.
        gpi_budget: Effort of each GPI identification.
        virtual_samples: Virtual (angle -> pressure) samples the inverse GPIs generate (the
            thesis used 150,000; a smooth, rate-independent generator at four frequencies
            gives the search no more information past a few tens of thousands).
        smooth_hz: Zero-phase low-pass of the measured angle before ``direct`` fits [Hz];
            0 to use it raw.
        preview_s: The loop's dead time, read from the plan ahead [s] (0: none). The chain
            is identified on each training recording's pressure paired with the bend
            ``preview_s`` later, and the compensator reads its set-point that much early
            (``preview_samples``, as the c-LSTM's). A DRDPI fitted across a dead time takes
            it up in its rate terms (the forward fit is as good with or without it: 0.889 vs
            0.887 deg on a plant with 40 ms of transport delay), but its inverse then lags:
            the same plant tracked 0.88 / 0.22 / 1.27 / 0.55 deg with the PI, 0.53 / 0.24 /
            0.69 / 0.45 deg with the 33 ms ``catheter-lab tune`` identified read ahead.
    """

    kind: ClassVar[str] = "idrdpi"
    direction = "inverse"
    requirement: ClassVar[DataRequirement] = DataRequirement(
        min_samples=2_500,
        why="The IDRDPI's 12 parameters need several hysteresis loops: 10 s at 250 Hz at least.",
    )

    params_: DRDPIParams
    coef_: FloatArray
    structure_: Structure
    gpis_: tuple[tuple[float, GPIParams], ...]

    def __init__(
        self,
        *,
        method: Method = "analytic",
        structure: Structure = "inverse",
        n_play: int = 10,
        n_deadband: int = 4,
        rate_filter_s: float = 0.02,
        bounds: Mapping[str, Sequence[float]] | None = None,
        budget: Budget | Mapping[str, Any] | None = None,
        seed: int = 0,
        grouping: Grouping = "auto",
        frequency_tolerance: float = 0.2,
        gpi_n_play: int = 10,
        gpi_budget: Budget | Mapping[str, Any] | None = None,
        virtual_samples: int = 50_000,
        smooth_hz: float = 10.0,
        preview_s: float = 0.0,
    ) -> None:
        if method not in METHODS:
            raise ParameterError(f"method = {method!r} must be one of {METHODS}")
        if structure not in STRUCTURES:
            raise ParameterError(f"structure = {structure!r} must be one of {STRUCTURES}")
        if method == "analytic" and structure != "inverse":
            raise ParameterError(
                "method 'analytic' inverts a fitted DRDPI, so its structure is 'inverse'; "
                f"got structure = {structure!r}"
            )
        if grouping not in GROUPINGS:
            raise ParameterError(f"grouping = {grouping!r} must be one of {GROUPINGS}")
        if not 0.0 < frequency_tolerance < 1.0:
            raise ParameterError(f"frequency_tolerance = {frequency_tolerance!r} must be in (0, 1)")
        if not (isinstance(virtual_samples, int) and virtual_samples >= 2_500):
            raise ParameterError(f"virtual_samples = {virtual_samples!r} must be >= 2500")
        if not (math.isfinite(smooth_hz) and smooth_hz >= 0.0):
            raise ParameterError(f"smooth_hz = {smooth_hz!r} must be >= 0 [Hz]")
        if not (
            isinstance(preview_s, (int, float))
            and math.isfinite(preview_s)
            and 0.0 <= preview_s <= MAX_PREVIEW_S
        ):
            raise ParameterError(
                f"preview_s = {preview_s!r} must be in [0, {MAX_PREVIEW_S}] s (a dead time, "
                "not a plan's length)"
            )
        # The forward DRDPI validates n_play, n_deadband, rate_filter_s, budget the same way.
        DRDPI(n_play=n_play, n_deadband=n_deadband, rate_filter_s=rate_filter_s)
        self.method: Method = method
        self.structure: Structure = structure
        self.n_play = n_play
        self.n_deadband = n_deadband
        self.rate_filter_s = float(rate_filter_s)
        default = DEFAULT_BOUNDS if structure == "inverse" else DRDPI_STRUCTURE_BOUNDS
        self.bounds = ParameterBounds.from_mapping(SEARCH_NAMES, {**default, **dict(bounds or {})})
        self.budget = Budget.coerce(budget)
        self.seed = int(seed)
        self.grouping: Grouping = grouping
        self.frequency_tolerance = float(frequency_tolerance)
        self.gpi_n_play = gpi_n_play
        self.gpi_budget = GPI(n_play=gpi_n_play, budget=gpi_budget).budget
        self.virtual_samples = virtual_samples
        self.smooth_hz = float(smooth_hz)
        self.preview_s = float(preview_s)

    # -- building from known parameters -----------------------------------------------------
    @classmethod
    def from_params(
        cls,
        params: DRDPIParams,
        rate_hz: float = SENSOR_RATE_HZ,
        structure: Structure = "inverse",
        **settings: Any,
    ) -> Self:
        """A fitted IDRDPI with given parameters (``inverse``: E⁻¹ of the DRDPI ``params``)."""
        method: Method = "analytic" if structure == "inverse" else "direct"
        model = cls(method=settings.pop("method", method), structure=structure, **settings)
        model._set_params(params, structure, rate_hz)
        return model

    def _set_params(self, params: DRDPIParams, structure: Structure, rate_hz: float) -> None:
        self.coef_ = chain_coefficients(
            params,
            n_play=self.n_play,
            n_deadband=self.n_deadband,
            rate_hz=rate_hz,
            rate_filter_s=self.rate_filter_s,
            inverse=structure == "inverse",
        )
        self.params_ = params
        self.structure_ = structure
        self.rate_hz_ = float(rate_hz)
        self.preview_samples = round(self.preview_s * self.rate_hz_)
        if not hasattr(self, "gpis_"):
            self.gpis_ = ()

    # -- fitting -----------------------------------------------------------------------------
    def fit(
        self,
        train: Sequence[Recording],
        validation: Sequence[Recording] = (),
        *,
        progress: bool = True,
    ) -> Self:
        """Find the chain's parameters by ``method`` (module docstring)."""
        t0 = time.perf_counter()
        rate = self._prepare(train, validation)
        lead = round(self.preview_s * rate)
        if lead:
            # Pressure now against the bend the dead time later: the chain without the delay.
            train = [_led(r, lead) for r in train]
        extra: dict[str, Any] = {
            "method": self.method,
            "structure": self.structure,
            "preview_samples": lead,
        }
        self.gpis_ = ()
        if self.method == "analytic":
            forward = DRDPI(
                n_play=self.n_play,
                n_deadband=self.n_deadband,
                rate_filter_s=self.rate_filter_s,
                bounds=self.bounds.to_mapping(),
                budget=self.budget,
                seed=self.seed,
            ).fit(train, validation, progress=progress)
            self._set_params(forward.params_, "inverse", rate)
            history = forward.fit_report_.train_loss
            extra["forward_fit"] = forward.fit_report_.to_dict()
        else:
            if self.method == "direct":
                angles = [smooth(rad_to_deg(r.angle_rad), rate, self.smooth_hz) for r in train]
                pressures = [pa_to_bar(r.pressure_pa) for r in train]
            else:
                angles, pressures, gpi_info = self._virtual_data(train, rate, progress)
                extra["gpi"] = gpi_info
            problem = DRDPIProblem(
                angles,
                pressures,
                n_play=self.n_play,
                n_deadband=self.n_deadband,
                rate_hz=rate,
                rate_filter_s=self.rate_filter_s,
                inverse=self.structure == "inverse",
            )
            params, result = identify_chain(
                problem,
                self.bounds,
                budget=self.budget,
                seed=self.seed,
                progress=progress,
                label=f"IDRDPI ({self.method})",
            )
            self._set_params(params, self.structure, rate)
            history = [*result.history, result.loss]
            extra["identification"] = result.summary()
            extra["training_samples"] = int(problem.x.size)
        extra["params"] = self.params_.to_dict()
        validation_loss: list[float] = []
        if validation:
            vrmse = {
                r.name: float(
                    np.sqrt(np.mean(pa_to_bar(self.predict(r.angle_rad) - r.pressure_pa) ** 2))
                )
                for r in validation
            }
            extra["validation_pressure_rmse_bar"] = vrmse
            validation_loss = [float(sum(v * v for v in vrmse.values()))]
        self.fit_report_ = FitReport(
            duration_s=time.perf_counter() - t0,
            train_loss=list(history),
            validation_loss=validation_loss,
            extra=extra,
        )
        return self

    def _virtual_data(
        self, train: Sequence[Recording], rate_hz: float, progress: bool
    ) -> tuple[list[FloatArray], list[FloatArray], list[dict[str, Any]]]:
        """Sec. 9.2 steps 1-2: a GPI per frequency, inverted, driven by desired angles."""
        groups = group_by_frequency(train, self.grouping, self.frequency_tolerance)
        per_group = max(2_500, self.virtual_samples // len(groups))
        angles: list[FloatArray] = []
        pressures: list[FloatArray] = []
        info: list[dict[str, Any]] = []
        gpis: list[tuple[float, GPIParams]] = []
        for group in groups:
            gpi = GPI(n_play=self.gpi_n_play, budget=self.gpi_budget, seed=self.seed).fit(
                list(group.recordings), progress=progress
            )
            peak_deg = max(float(np.max(rad_to_deg(r.angle_rad))) for r in group.recordings)
            # Where the GPI cannot reach a desired angle, γ⁻¹ saturates far outside the
            # valve's range; the rig would have stopped at the range the group was driven
            # over, so the virtual pressure does too.
            p_low = min(float(np.min(r.pressure_pa)) for r in group.recordings)
            p_high = max(float(np.max(r.pressure_pa)) for r in group.recordings)
            for desired_deg in virtual_angle_signals(
                group.frequency_hz, peak_deg, per_group, rate_hz
            ):
                pressure_pa = np.clip(gpi.inverse_predict(deg_to_rad(desired_deg)), p_low, p_high)
                angles.append(desired_deg)
                pressures.append(pa_to_bar(pressure_pa))
            gpis.append((group.frequency_hz, gpi.params_))
            info.append(
                {
                    "frequency_hz": group.frequency_hz,
                    "recordings": [r.name for r in group.recordings],
                    "params": gpi.params_.to_dict(),
                    "loss": gpi.fit_report_.extra["identification"]["loss"],
                }
            )
        self.gpis_ = tuple(gpis)
        return angles, pressures, info

    # -- running -----------------------------------------------------------------------------
    def _coef(self) -> FloatArray:
        coef: FloatArray | None = getattr(self, "coef_", None)
        if coef is None:
            raise NotFittedError("idrdpi model is not fitted: call fit() or load() first")
        return coef

    def predict(self, input_si: npt.ArrayLike) -> FloatArray:
        """Pressure [Pa gauge] for a desired-angle signal [rad], from rest (not clamped)."""
        coef = self._coef()
        x = read_ahead(rad_to_deg(as_input(input_si, "angle_rad")), self.preview_samples)
        out: FloatArray = bar_to_pa(run_chain(coef, x))
        return out

    def stream(self) -> ChainStream:
        """The compensator: rad in, Pa out, equal to :meth:`predict` sample by sample.

        With a preview, ``step`` takes the set-point ``preview_samples`` ahead, as the node
        feeds it.
        """
        return ChainStream(self._coef(), rad_to_deg, bar_to_pa, self.kind)

    # -- persistence -------------------------------------------------------------------------
    def _settings(self) -> dict[str, Any]:
        return {
            "method": self.method,
            "structure": self.structure,
            "n_play": self.n_play,
            "n_deadband": self.n_deadband,
            "rate_filter_s": self.rate_filter_s,
            "bounds": self.bounds.to_mapping(),
            "budget": self.budget.to_dict(),
            "seed": self.seed,
            "grouping": self.grouping,
            "frequency_tolerance": self.frequency_tolerance,
            "gpi_n_play": self.gpi_n_play,
            "gpi_budget": self.gpi_budget.to_dict(),
            "virtual_samples": self.virtual_samples,
            "smooth_hz": self.smooth_hz,
            "preview_s": self.preview_s,
        }

    def _payload(self) -> dict[str, bytes]:
        self._coef()
        units = FORWARD_UNITS if self.structure_ == "inverse" else DRDPI_STRUCTURE_UNITS
        structure = {
            "n_play": self.n_play,
            "n_deadband": self.n_deadband,
            "rate_filter_s": self.rate_filter_s,
        }
        meta = {
            "format": IDRDPI_META_FORMAT,
            "structure": self.structure_,
            "chain": "E_theta^-1 (eqs. 9.2-9.11)"
            if self.structure_ == "inverse"
            else "Z(PI(angle)) (eqs. 5.1-5.11, angle in)",
            "gpis": [{"frequency_hz": f, "params": p.to_dict()} for f, p in self.gpis_],
        }
        return {
            PARAMS_FILE: DRDPI_PARAMS_FILE.dump(self.params_, units, structure),
            IDRDPI_META_FILE: (json.dumps(meta, indent=2) + "\n").encode(),
        }

    @classmethod
    def _from_payload(cls, manifest: Manifest, payload: Mapping[str, bytes]) -> Self:
        params, structure_settings = DRDPI_PARAMS_FILE.read(payload, kind=cls.kind)
        raw_meta = payload.get(IDRDPI_META_FILE)
        if raw_meta is None:
            raise ModelError(f"idrdpi model directory lacks {IDRDPI_META_FILE}")
        try:
            meta = json.loads(raw_meta)
            if meta.get("format") != IDRDPI_META_FORMAT:
                raise ModelError(
                    f"{IDRDPI_META_FILE} has format {meta.get('format')!r}, "
                    f"expected {IDRDPI_META_FORMAT!r}"
                )
            structure = meta["structure"]
            if structure not in STRUCTURES:
                raise ModelError(f"{IDRDPI_META_FILE}: unknown structure {structure!r}")
            gpis = tuple(
                (float(g["frequency_hz"]), GPIParams.from_dict(g["params"]))
                for g in meta.get("gpis", [])
            )
            settings = dict(manifest.metrics.get("settings", {}))
            settings.update(structure_settings)
            settings["structure"] = structure
            model = cls(**settings)
        except (ValueError, KeyError, TypeError, AttributeError) as exc:
            raise ModelError(f"idrdpi: model files are malformed: {exc}") from None
        rate = saved_rate_hz(manifest, cls.kind)
        model.gpis_ = gpis
        model._set_params(params, structure, rate)
        return model


__all__ = [
    "DRDPI_STRUCTURE_BOUNDS",
    "DRDPI_STRUCTURE_UNITS",
    "IDRDPI",
    "FrequencyGroup",
    "dominant_frequency_hz",
    "frequency_tag_hz",
    "group_by_frequency",
    "virtual_angle_signals",
]
