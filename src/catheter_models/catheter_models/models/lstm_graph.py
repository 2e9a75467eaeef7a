"""What the LSTM's inference and its training share: the settings and the exported graph's spec.

An LSTM or c-LSTM is trained with torch (:mod:`catheter_models.models.lstm_train`) and run with
ONNX Runtime (:mod:`catheter_models.models.lstm`). Both sides must agree on the settings, on
the names of the graph's inputs and outputs and on the metadata the graph carries; those live
here, in their own module, so that training depends on this contract and not on the inference
module, and inference imports training only when :meth:`fit` is called (torch stays out of
the compensator node). Neither of the two imports the other at module level.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields
from typing import Any, Final, Literal

from catheter_models.errors import ParameterError
from catheter_models.models.base import MinMaxScaler, ModelError

Form = Literal["streaming", "windowed"]
ValidationSplit = Literal["recordings", "time"]
FORMS: Final[tuple[Form, ...]] = ("streaming", "windowed")

ONNX_FILE: Final = "model.onnx"
METADATA_KEY: Final = "catheter_models.lstm"
"""Key of the graph's metadata entry that repeats form, sizes, preview and normalisation."""

# Names of the graph's inputs and outputs, shared with the exporter.
INPUT_NAME: Final = "x"
OUTPUT_NAME: Final = "y"
STATE_INPUTS: Final = ("h0", "c0")
STATE_OUTPUTS: Final = ("hn", "cn")


@dataclass(frozen=True)
class LSTMSettings:
    """Network shape, inference form and training settings of an LSTM or c-LSTM.

    Attributes:
        form: ``"streaming"`` (stateful, real time) or ``"windowed"`` (thesis).
        hidden_size: Units per LSTM layer (thesis: 64 for the LSTM, 128 for the c-LSTM).
        num_layers: Stacked LSTM layers (thesis: 2).
        window_samples: Window length of the windowed form [samples] (thesis: 50).
        preview_samples: The input leads the output by this many samples (c-LSTM: the
            set-point ``preview_samples`` ticks ahead); 0 for none.
        learning_rate: Adam's initial learning rate (thesis: 1e-3).
        final_learning_rate: Learning rate at the end of the cosine schedule, reached at
            ``max_epochs`` or at ``time_budget_s``, whichever comes first.
        batch_size: Sequences per batch (streaming) or windows per batch (windowed; thesis 16).
        chunk_samples: Truncated back-propagation length of the streaming form [samples];
            the hidden state is carried, detached, from chunk to chunk.
        window_stride: Train (and validate) the windowed form on every n-th window only.
        max_epochs: Upper bound on passes over the training data.
        patience_epochs: Stop when validation loss has not improved for this many epochs.
        time_budget_s: Wall-time budget of training [s]; the best epoch so far is kept.
        validation_fraction: Share of the data held out for validation (thesis: 0.3).
        validation_split: ``"recordings"``: hold out whole recordings (at least one stays for
            training); ``"time"``: hold out the last part of every recording.
        input_noise_si: Std of Gaussian noise added to the training input, in the input's SI
            unit (rad for the c-LSTM, Pa for the LSTM); 0 for none.
        input_smoothing_hz: Cut-off [Hz] of a zero-phase low-pass filter applied to the
            training input before anything else; 0 for none. For the c-LSTM, whose training
            input is the laser's noisy angle but whose run-time input is a smooth set-point:
            a network that must average sensor noise away learns a lagging filter.
        rest_weight: Loss weight of samples whose input is at rest (within 1% of its range
            from the training minimum), where the output cannot be told from the input (the
            deadband: pressure rises from 0 to opening with the tip still straight); 1 keeps
            the plain L2 loss.
        grad_clip_norm: Gradients are clipped to this global norm (LSTM training stability).
        seed: Seeds the split, the batch order, the noise and the initial weights.
        num_threads: torch intra-op threads while training. One by default: on a machine
            whose cores are shared with other jobs, two OpenMP threads spin-wait on each other
            at every LSTM time step; measured here with one core busy elsewhere, a 2 x 128
            update took 0.1-13 s with two threads against a steady 85 ms with one.
    """

    form: Form = "streaming"
    hidden_size: int = 64
    num_layers: int = 2
    window_samples: int = 50
    preview_samples: int = 0
    learning_rate: float = 1e-3
    final_learning_rate: float = 1e-4
    batch_size: int = 16
    chunk_samples: int = 250
    window_stride: int = 4
    max_epochs: int = 200
    patience_epochs: int = 30
    time_budget_s: float = 600.0
    validation_fraction: float = 0.3
    validation_split: ValidationSplit = "recordings"
    input_noise_si: float = 0.0
    input_smoothing_hz: float = 0.0
    rest_weight: float = 1.0
    grad_clip_norm: float = 1.0
    seed: int = 0
    num_threads: int = 1

    def __post_init__(self) -> None:
        if self.form not in FORMS:
            raise ParameterError(f"form must be one of {FORMS}, got {self.form!r}")
        if self.validation_split not in ("recordings", "time"):
            raise ParameterError(
                f"validation_split must be 'recordings' or 'time', got {self.validation_split!r}"
            )
        positive_ints = {
            "hidden_size": self.hidden_size,
            "num_layers": self.num_layers,
            "window_samples": self.window_samples,
            "batch_size": self.batch_size,
            "chunk_samples": self.chunk_samples,
            "window_stride": self.window_stride,
            "max_epochs": self.max_epochs,
            "patience_epochs": self.patience_epochs,
            "num_threads": self.num_threads,
        }
        for name, value in positive_ints.items():
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ParameterError(f"{name} must be an integer >= 1, got {value!r}")
        if not isinstance(self.preview_samples, int) or self.preview_samples < 0:
            raise ParameterError(
                f"preview_samples must be an integer >= 0, got {self.preview_samples!r}"
            )
        if not isinstance(self.seed, int):
            raise ParameterError(f"seed must be an integer, got {self.seed!r}")
        positive_floats = {
            "learning_rate": self.learning_rate,
            "final_learning_rate": self.final_learning_rate,
            "time_budget_s": self.time_budget_s,
            "grad_clip_norm": self.grad_clip_norm,
        }
        for name, number in positive_floats.items():
            if not (math.isfinite(number) and number > 0.0):
                raise ParameterError(f"{name} must be finite and > 0, got {number!r}")
        if not 0.0 < self.validation_fraction < 1.0:
            raise ParameterError(
                f"validation_fraction must be in (0, 1), got {self.validation_fraction!r}"
            )
        for name, number in {
            "input_noise_si": self.input_noise_si,
            "input_smoothing_hz": self.input_smoothing_hz,
        }.items():
            if not (math.isfinite(number) and number >= 0.0):
                raise ParameterError(f"{name} must be finite and >= 0, got {number!r}")
        if not (math.isfinite(self.rest_weight) and 0.0 <= self.rest_weight <= 1.0):
            raise ParameterError(f"rest_weight must be in [0, 1], got {self.rest_weight!r}")

    @classmethod
    def from_dict(cls, raw: Mapping[str, Any]) -> LSTMSettings:
        """Rebuild from :func:`dataclasses.asdict` output; unknown keys are refused by name."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(raw) - known)
        if unknown:
            raise ModelError(f"unknown LSTM settings {unknown}; known: {sorted(known)}")
        return cls(**dict(raw))


@dataclass(frozen=True)
class GraphSpec:
    """What an exported graph is: written into its metadata, checked against the manifest.

    Attributes:
        kind: Model kind (``"lstm"`` or ``"clstm"``).
        form: ``"streaming"`` or ``"windowed"``.
        hidden_size: Units per layer.
        num_layers: Stacked layers.
        window_samples: Window length of the windowed form [samples].
        preview_samples: Input lead over the output [samples].
        input_scaler: Eq. 7.9 range of the input (SI).
        output_scaler: Eq. 7.9 range of the output (SI).
    """

    kind: str
    form: Form
    hidden_size: int
    num_layers: int
    window_samples: int
    preview_samples: int
    input_scaler: MinMaxScaler
    output_scaler: MinMaxScaler

    def to_json(self) -> str:
        """Stable JSON for the graph's metadata."""
        raw = asdict(self)
        return json.dumps(raw, sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> GraphSpec:
        """Inverse of :meth:`to_json`; ModelError if malformed."""
        try:
            raw = json.loads(text)
            form = raw["form"]
            if form not in FORMS:
                raise ValueError(f"form {form!r}")
            return cls(
                kind=str(raw["kind"]),
                form=form,
                hidden_size=int(raw["hidden_size"]),
                num_layers=int(raw["num_layers"]),
                window_samples=int(raw["window_samples"]),
                preview_samples=int(raw["preview_samples"]),
                input_scaler=MinMaxScaler.from_dict(raw["input_scaler"]),
                output_scaler=MinMaxScaler.from_dict(raw["output_scaler"]),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise ModelError(f"the graph's {METADATA_KEY!r} metadata is malformed: {exc}") from None


__all__ = [
    "FORMS",
    "INPUT_NAME",
    "METADATA_KEY",
    "ONNX_FILE",
    "OUTPUT_NAME",
    "STATE_INPUTS",
    "STATE_OUTPUTS",
    "Form",
    "GraphSpec",
    "LSTMSettings",
    "ValidationSplit",
]
