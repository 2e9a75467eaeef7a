"""What every identified model shares: recordings in, one contract for fit/predict/stream/save.

A model maps one signal to another at a fixed sample rate:

* ``forward`` models (DRDPI, GPI, SVR, LSTM) map the valve command ``pressure_pa`` to the
  bend ``angle_rad``; they answer "what will the catheter do".
* ``inverse`` models (IDRDPI, c-LSTM) map a desired ``angle_rad`` to the ``pressure_pa`` that
  produces it; they are the feedforward compensators the compensator node runs.

The contract follows scikit-learn, as PySINDy does: ``__init__`` only stores settings,
``fit`` returns ``self``, and everything learned ends in ``_``. Arrays at this boundary are SI
(Pa gauge, rad, s); a model may work internally in the thesis's bar and degrees so that its
parameters read like the thesis's tables, and says so.

``predict`` runs a whole recording from rest; ``stream()`` returns a stateful object whose
``step`` takes one sample at a time, for the real-time loop. Both run the same code (the
numba operators, or the same ONNX graph), and a test checks that they agree.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path, PurePath
from typing import TYPE_CHECKING, Any, ClassVar, Literal, Protocol

import numpy as np
import numpy.typing as npt

from catheter_models.contract import ANGLE_DESIRED, PRESSURE_COMMAND, SENSOR_RATE_HZ, TIP_ANGLE
from catheter_models.errors import CatheterError, ParameterError, SignalError
from catheter_models.model_dir import Manifest, read_model_dir, write_model_dir

if TYPE_CHECKING:
    from typing import Self  # 3.11+; annotations only, so 3.10 imports the module

FloatArray = npt.NDArray[np.float64]
Direction = Literal["forward", "inverse"]


class ModelError(CatheterError):
    """A model cannot be built, fitted or used as asked. The message says what is wrong."""


class NotFittedError(ModelError):
    """``predict``, ``stream`` or ``save`` was called before ``fit`` or ``load``."""


class InsufficientDataError(ModelError, ValueError):
    """Too little training data; the message says how much more is needed."""


class RateMismatchError(ModelError, ValueError):
    """A recording's sample rate differs from the rate the model was fitted at."""


# The signals of the contract the models speak of, with units, as written into manifests.
PRESSURE_SIGNAL: Mapping[str, str] = {PRESSURE_COMMAND.name: "Pa"}
ANGLE_SIGNAL: Mapping[str, str] = {TIP_ANGLE.name: "rad"}
DESIRED_ANGLE_SIGNAL: Mapping[str, str] = {ANGLE_DESIRED.name: "rad"}


@dataclass(frozen=True, eq=False)
class Recording:
    """One experiment on a uniform time grid: valve command in, measured bend out.

    Attributes:
        name: Where it came from (bag file name, or the signal preset).
        rate_hz: Sample rate [Hz].
        pressure_pa: Valve set-point [Pa gauge], the input the compensator controls.
        angle_rad: Measured bend angle [rad].
        source: Bag path, or ``simulated:<preset>``.
        sha256: Hash of the bag's files (recorded in a model's manifest), or "" if simulated.
        measurement_age_s: How old a bend sample was when it arrived (the bag's
            ``tip/angle`` arrival age), 0 if unknown or simulated. The grid is on the stamps,
            the time the bend was true; a feedback loop sees it this much later (``tune``).
    """

    name: str
    rate_hz: float
    pressure_pa: FloatArray
    angle_rad: FloatArray
    source: str = ""
    sha256: str = ""
    measurement_age_s: float = 0.0

    def __post_init__(self) -> None:
        p = np.ascontiguousarray(self.pressure_pa, dtype=np.float64)
        a = np.ascontiguousarray(self.angle_rad, dtype=np.float64)
        if p.ndim != 1 or a.ndim != 1 or p.size != a.size:
            raise SignalError(
                f"recording {self.name!r}: pressure and angle must be 1-D and equally long, "
                f"got shapes {p.shape} and {a.shape}"
            )
        for label, arr in (("pressure_pa", p), ("angle_rad", a)):
            bad = np.flatnonzero(~np.isfinite(arr))
            if bad.size:
                raise SignalError(
                    f"recording {self.name!r}: {label} has {bad.size} non-finite samples "
                    f"(first at index {bad[0]}); repair or trim the bag before training"
                )
        if not (math.isfinite(self.rate_hz) and self.rate_hz > 0.0):
            raise ParameterError(f"recording {self.name!r}: rate_hz {self.rate_hz!r} must be > 0")
        p.setflags(write=False)
        a.setflags(write=False)
        object.__setattr__(self, "pressure_pa", p)
        object.__setattr__(self, "angle_rad", a)

    def __len__(self) -> int:
        return int(self.pressure_pa.size)

    @property
    def bag_name(self) -> str:
        """How a model's manifest names this recording: the bag's file or directory name.

        Never the path: a path is the training machine's and means nothing where the model
        is shipped; the name and :attr:`sha256` are enough to find the bag in any bags
        directory and prove it is the one (``models.data.locate_training_bags``). A recording
        without a source keeps its name; a simulated one, ``simulated:<preset>``.
        """
        return PurePath(self.source).name if self.source else self.name

    @property
    def duration_s(self) -> float:
        """Length of the recording [s]."""
        return len(self) / self.rate_hz

    def io(self, direction: Direction) -> tuple[FloatArray, FloatArray]:
        """(input, output) arrays for a model of ``direction``, SI."""
        if direction == "forward":
            return self.pressure_pa, self.angle_rad
        return self.angle_rad, self.pressure_pa


class Stream(Protocol):
    """A model stepped one sample at a time, state carried between steps.

    The same shape as ``catheter_control``'s ``StreamingCompensator``: an inverse model's
    stream *is* a compensator.
    """

    def reset(self) -> None:
        """Return to the state at rest (as at the start of a recording)."""

    def step(self, value: float) -> float:
        """Advance one sample: input in SI, output in SI."""


@dataclass(frozen=True)
class MinMaxScaler:
    """Thesis eq. 7.9: map [lo, hi] linearly onto [-1, 1] (and back).

    Attributes:
        lo: Value mapped to -1 (the training minimum).
        hi: Value mapped to +1 (the training maximum).
    """

    lo: float
    hi: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.lo) and math.isfinite(self.hi) and self.hi > self.lo):
            raise ModelError(
                f"normalisation range [{self.lo}, {self.hi}] is empty or not finite: "
                "the training signal must vary"
            )

    @classmethod
    def fit(cls, values: npt.ArrayLike) -> MinMaxScaler:
        """Range of ``values``."""
        arr = np.asarray(values, dtype=np.float64)
        return cls(float(np.min(arr)), float(np.max(arr)))

    def transform(self, values: npt.ArrayLike) -> FloatArray:
        """Eq. 7.9 with a = -1, b = 1."""
        arr = np.asarray(values, dtype=np.float64)
        return 2.0 * (arr - self.lo) / (self.hi - self.lo) - 1.0

    def inverse(self, values: npt.ArrayLike) -> FloatArray:
        """Undo :meth:`transform`."""
        arr = np.asarray(values, dtype=np.float64)
        return (arr + 1.0) * 0.5 * (self.hi - self.lo) + self.lo

    def to_dict(self) -> dict[str, float]:
        """For the manifest's ``normalization`` entry."""
        return {"lo": self.lo, "hi": self.hi}

    @classmethod
    def from_dict(cls, raw: Mapping[str, Any]) -> MinMaxScaler:
        """Inverse of :meth:`to_dict`; ModelError if malformed."""
        try:
            return cls(float(raw["lo"]), float(raw["hi"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise ModelError(f"normalisation entry {dict(raw)!r} is malformed: {exc}") from None


@dataclass(frozen=True)
class DataRequirement:
    """How much training data a model kind needs before fitting means anything."""

    min_samples: int
    min_recordings: int = 1
    why: str = ""

    def check(self, kind: str, recordings: Sequence[Recording]) -> None:
        """Raise InsufficientDataError saying how much more is needed."""
        n = sum(len(r) for r in recordings)
        if len(recordings) < self.min_recordings:
            raise InsufficientDataError(
                f"{kind}: {len(recordings)} training recording(s) given, at least "
                f"{self.min_recordings} needed ({self.min_recordings - len(recordings)} more). "
                f"{self.why}".strip()
            )
        if n < self.min_samples:
            rate = recordings[0].rate_hz if recordings else SENSOR_RATE_HZ
            more = self.min_samples - n
            raise InsufficientDataError(
                f"{kind}: {n} training samples given, at least {self.min_samples} needed: "
                f"record {more} more samples (≈ {more / rate:.0f} s at {rate:g} Hz). "
                f"{self.why}".strip()
            )


def check_rates(kind: str, recordings: Sequence[Recording], rate_hz: float | None = None) -> float:
    """All recordings share one rate (and equal ``rate_hz`` if given); returns it."""
    if not recordings:
        raise InsufficientDataError(f"{kind}: no recordings given")
    expected = rate_hz if rate_hz is not None else recordings[0].rate_hz
    off = [r for r in recordings if not math.isclose(r.rate_hz, expected, rel_tol=1e-6)]
    if off:
        raise RateMismatchError(
            f"{kind}: recording {off[0].name!r} is sampled at {off[0].rate_hz:g} Hz, "
            f"but the model works at {expected:g} Hz; resample it (BagData.aligned(rate_hz=...))"
        )
    return float(expected)


@dataclass
class FitReport:
    """What a fit did, for the CLI, benchmarks and the manifest."""

    duration_s: float = 0.0
    train_loss: list[float] = field(default_factory=list)
    validation_loss: list[float] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able summary (curves thinned to at most 200 points)."""

        def thin(values: list[float]) -> list[float]:
            step = max(1, len(values) // 200)
            return [float(v) for v in values[::step]]

        return {
            "duration_s": self.duration_s,
            "train_loss": thin(self.train_loss),
            "validation_loss": thin(self.validation_loss),
            **self.extra,
        }


class Model(ABC):
    """Base of every identified model. Subclasses set ``kind`` and ``direction``.

    Subclasses implement ``fit``, ``predict``, ``stream``, ``_payload`` (weight files as
    bytes, never pickle), ``_from_payload`` and ``_settings`` (the constructor arguments, so
    that a loaded model can be refitted with the same settings).
    """

    kind: ClassVar[str]
    direction: ClassVar[Direction]
    requirement: ClassVar[DataRequirement] = DataRequirement(min_samples=2_500)
    preview_samples: int = 0
    """How far ahead of now an inverse model reads its set-point [samples] (0: none). A
    compensator follows a plan it knows in advance, so a model may be trained to read the
    desired angle a few samples early and so cover the valve's and muscle's lag."""

    rate_hz_: float
    fit_report_: FitReport

    # -- the scikit-learn-like contract ------------------------------------------------------
    @abstractmethod
    def fit(
        self,
        train: Sequence[Recording],
        validation: Sequence[Recording] = (),
        *,
        progress: bool = True,
    ) -> Self:
        """Identify the model from ``train``; ``validation`` is for early stopping/selection."""

    @abstractmethod
    def predict(self, input_si: npt.ArrayLike) -> FloatArray:
        """Run a whole input signal from rest; SI in, SI out, same length."""

    @abstractmethod
    def stream(self) -> Stream:
        """A fresh stateful stepper at rest, equivalent to :meth:`predict` sample by sample."""

    def predict_recording(self, recording: Recording) -> FloatArray:
        """Model output for ``recording``'s input (checks the sample rate first)."""
        check_rates(self.kind, [recording], self.fitted_rate_hz)
        x, _ = recording.io(self.direction)
        return self.predict(x)

    @property
    def fitted_rate_hz(self) -> float:
        """The rate the model was fitted at; NotFittedError before fit/load."""
        rate = getattr(self, "rate_hz_", None)
        if rate is None:
            raise NotFittedError(f"{self.kind} model is not fitted: call fit() or load() first")
        return float(rate)

    def _prepare(self, train: Sequence[Recording], validation: Sequence[Recording]) -> float:
        """Common checks at the start of ``fit``: enough data, one sample rate."""
        self.requirement.check(self.kind, train)
        rate = check_rates(self.kind, list(train) + list(validation))
        self.rate_hz_ = rate
        return rate

    # -- persistence -------------------------------------------------------------------------
    @abstractmethod
    def _payload(self) -> dict[str, bytes]:
        """Weight files of the fitted model, by file name."""

    @abstractmethod
    def _settings(self) -> dict[str, Any]:
        """Constructor arguments (JSON-able)."""

    @classmethod
    @abstractmethod
    def _from_payload(cls, manifest: Manifest, payload: Mapping[str, bytes]) -> Self:
        """Rebuild a fitted model from a verified directory."""

    def settings(self) -> dict[str, Any]:
        """The model's settings (constructor arguments), as the manifest records them."""
        return dict(self._settings())

    def _normalization(self) -> dict[str, Any]:
        """Normalisation constants for the manifest (override where used)."""
        return {}

    def signals(self) -> tuple[Mapping[str, str], Mapping[str, str]]:
        """(inputs, outputs) with units, as the manifest records them."""
        if self.direction == "forward":
            return PRESSURE_SIGNAL, ANGLE_SIGNAL
        return DESIRED_ANGLE_SIGNAL, PRESSURE_SIGNAL

    def save(
        self,
        path: Path | str,
        training: Sequence[Recording] = (),
        metrics: Mapping[str, Any] | None = None,
    ) -> Manifest:
        """Write a model directory (``docs/interfaces.md``); refuses to overwrite one."""
        rate = self.fitted_rate_hz
        inputs, outputs = self.signals()
        report = getattr(self, "fit_report_", FitReport())
        return write_model_dir(
            Path(path),
            self.kind,
            inputs,
            outputs,
            self._payload(),
            normalization=self._normalization(),
            training_bags={r.bag_name: r.sha256 for r in training},
            metrics={
                "rate_hz": rate,
                "direction": self.direction,
                "settings": self._settings(),
                "fit": report.to_dict(),
                **dict(metrics or {}),
            },
        )

    @classmethod
    def load(cls, path: Path | str) -> Self:
        """Read and hash-check a model directory of this kind."""
        manifest, payload = read_model_dir(Path(path), expected_kind=cls.kind)
        model = cls._from_payload(manifest, payload)
        try:
            model.rate_hz_ = float(manifest.metrics["rate_hz"])
        except (KeyError, TypeError, ValueError):
            raise ModelError(f"{path}: manifest metrics lack a valid 'rate_hz'") from None
        return model


def saved_rate_hz(manifest: Manifest, kind: str) -> float:
    """The rate a saved model was fitted at, from its manifest; ModelError if it is missing."""
    rate = manifest.metrics.get("rate_hz")
    if not isinstance(rate, (int, float)):
        raise ModelError(f"{kind} manifest metrics lack a valid 'rate_hz'")
    return float(rate)


def as_input(values: npt.ArrayLike, name: str = "input") -> FloatArray:
    """A finite 1-D float64 array, or SignalError naming the first bad sample."""
    arr = np.ascontiguousarray(values, dtype=np.float64)
    if arr.ndim != 1:
        raise SignalError(f"{name} must be 1-D, got shape {arr.shape}")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise SignalError(f"{name} has {bad.size} non-finite samples (first at index {bad[0]})")
    return arr


def check_finite_step(value: float, kind: str) -> float:
    """Refuse a NaN/inf sample in a stream: a compensator must never emit garbage."""
    v = float(value)
    if not math.isfinite(v):
        raise SignalError(f"{kind} stream: input sample {v!r} is not finite")
    return v


# -- a preview: the plan read ahead across the loop's dead time ----------------------------------
# One definition for every compensator that reads ahead (the c-LSTM, the IDRDPI), so training
# pairs, ``predict`` and the node's feed (``evaluate.track``, the compensator node) agree.


def paired_ahead(
    inputs: FloatArray, outputs: FloatArray, lead: int
) -> tuple[FloatArray, FloatArray]:
    """Training pairs for a compensator with a preview: ``inputs[k + lead]`` with ``outputs[k]``.

    An inverse model so trained maps the bend wanted ``lead`` samples from now to the pressure
    to command now, which is what a loop with that dead time needs.
    """
    if lead <= 0:
        return inputs, outputs
    return inputs[lead:], outputs[: outputs.size - lead]


def read_ahead(signal: FloatArray, lead: int) -> FloatArray:
    """``signal`` read ``lead`` samples ahead, its last value held past its end.

    What a compensator with a preview is fed over a whole signal, as the node feeds it the
    set-point ``lead`` ticks ahead of the plan's clock, holding the plan's last point.
    """
    if lead <= 0 or signal.size == 0:
        return signal
    return np.concatenate([signal[lead:], np.full(min(lead, signal.size), signal[-1])])
