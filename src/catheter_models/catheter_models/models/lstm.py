"""The thesis's LSTM forward model (ch. 7) and c-LSTM inverse compensator (ch. 10), on ONNX.

Inference only: this module never imports torch, so the compensator node runs a c-LSTM with
ONNX Runtime alone. Training lives in :mod:`catheter_models.models.lstm_train`, imported
inside :meth:`fit`; what both sides share (settings, graph spec, input and output names) lives
in :mod:`catheter_models.models.lstm_graph`, so training never imports this module.

Both kinds share one implementation and come in two *forms* (the ``form`` setting):

``"streaming"`` (the default, the real-time form)
    One LSTM run from rest over the whole signal. The ONNX graph takes ``x`` [T, 1, 1] with the
    hidden and cell states ``h0``, ``c0`` [layers, 1, hidden] and returns ``y`` [T, 1, 1],
    ``hn``, ``cn``. :meth:`predict` runs the whole sequence in one call from zero state;
    :meth:`stream` feeds one sample per call and passes the state back in, so a tick costs one
    LSTM cell step (``docs/compensator.md``).
``"windowed"`` (the thesis's form)
    Each output comes from the last 50 inputs (eq. 7.4's window), left-padded with the signal
    at rest. The graph takes ``x`` [B, 50, 1] and returns ``y`` [B, 1]; :meth:`predict`
    batches the windows, :meth:`stream` keeps a 50-sample ring buffer and reruns the window
    every tick (50 cell steps a tick: kept for fidelity and comparison, not for the node).

Normalisation (thesis eq. 7.9, inputs and outputs onto [-1, 1]) is applied *outside* the
graph, with the constants from the manifest's ``normalization`` entry: the manifest is where
``docs/interfaces.md`` puts them, so the node and the lab can read the range a model was
trained on (and refuse or flag set-points outside it) without opening the graph, and the
graph stays the network exactly as trained, which is what the torch-vs-ONNX check compares.
Because the manifest itself is not hashed, the same constants are also written into the
graph's metadata (hashed with ``model.onnx``), and loading refuses a model whose two copies
disagree: a hand-edited range must never silently rescale pressure commands.

The c-LSTM may be given a *preview* (``preview_samples`` = L): it is trained to map the bend
measured L samples later to today's pressure, which covers the valve and tip lag. A
compensator knows its plan ahead, so its stream's :meth:`~Stream.step` takes the set-point
L ticks ahead; :meth:`predict`, which has the whole signal, does that shift itself (holding the
last value past the end). The manifest records ``preview_samples`` so the node knows.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Final

import numpy as np
import numpy.typing as npt

from catheter_models.errors import ParameterError
from catheter_models.model_dir import Manifest, ModelDirError
from catheter_models.models.base import (
    DataRequirement,
    Direction,
    FloatArray,
    MinMaxScaler,
    Model,
    ModelError,
    NotFittedError,
    Recording,
    Stream,
    as_input,
    check_finite_step,
    read_ahead,
)
from catheter_models.models.lstm_graph import (
    FORMS,
    INPUT_NAME,
    METADATA_KEY,
    ONNX_FILE,
    OUTPUT_NAME,
    STATE_INPUTS,
    STATE_OUTPUTS,
    Form,
    GraphSpec,
    LSTMSettings,
    ValidationSplit,
)
from catheter_models.onnx_runtime import ort

if TYPE_CHECKING:
    from typing import Self  # 3.11+; annotations only, so 3.10 imports the module

_PREDICT_BATCH_WINDOWS: Final = 4096
"""Windows per ONNX call in windowed :meth:`predict`: bounds memory to about 1 MB a batch."""


def session_options() -> ort.SessionOptions:
    """ONNX Runtime settings for a real-time tick: one thread, sequential, fully optimised.

    One intra-op thread because a single LSTM step is far too small to gain from threads and
    the node's loop must not compete with its own worker pool for the CPU.
    """
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    options.inter_op_num_threads = 1
    options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    options.log_severity_level = 3  # warnings about unused initialisers are noise here
    return options


def open_session(onnx_bytes: bytes) -> tuple[ort.InferenceSession, GraphSpec]:
    """An ONNX Runtime session for an exported LSTM graph, and the spec in its metadata.

    Raises:
        ModelError: The bytes are no ONNX model, lack the metadata, or the graph's inputs and
            outputs are not those of the form its metadata names.
    """
    try:
        session = ort.InferenceSession(
            onnx_bytes, sess_options=session_options(), providers=["CPUExecutionProvider"]
        )
    except Exception as exc:  # ORT raises its own untyped exception classes
        raise ModelError(f"{ONNX_FILE} is not a loadable ONNX model: {exc}") from None
    meta = session.get_modelmeta().custom_metadata_map
    if METADATA_KEY not in meta:
        raise ModelError(
            f"{ONNX_FILE} lacks its {METADATA_KEY!r} metadata: it was not exported by "
            "catheter_models.models.lstm_train"
        )
    spec = GraphSpec.from_json(meta[METADATA_KEY])
    inputs = [i.name for i in session.get_inputs()]
    outputs = [o.name for o in session.get_outputs()]
    if spec.form == "streaming":
        want_in, want_out = [INPUT_NAME, *STATE_INPUTS], [OUTPUT_NAME, *STATE_OUTPUTS]
    else:
        want_in, want_out = [INPUT_NAME], [OUTPUT_NAME]
    if inputs != want_in or outputs != want_out:
        raise ModelError(
            f"{ONNX_FILE}: a {spec.form} graph must have inputs {want_in} and outputs "
            f"{want_out}, this one has {inputs} and {outputs}"
        )
    return session, spec


REST_SETTLE_SAMPLES: Final = 500
"""How long the network is held at the rest input to find its state at rest (2 s at 250 Hz)."""


def rest_state(
    session: ort.InferenceSession, spec: GraphSpec
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]:
    """The hidden and cell state of a streaming graph after it has been held at rest.

    Zero state is not where the network sits when the catheter has been at rest for a
    while: started from zeros, the first few outputs swing (11 deg at t = 0 on a forward model
    before this). Every recording starts at rest, so every run starts from this state.
    """
    zeros = np.zeros((spec.num_layers, 1, spec.hidden_size), dtype=np.float32)
    rest = np.float32(spec.input_scaler.transform(0.0))
    x = np.full((REST_SETTLE_SAMPLES, 1, 1), rest, dtype=np.float32)
    _, h, c = session.run(None, {INPUT_NAME: x, STATE_INPUTS[0]: zeros, STATE_INPUTS[1]: zeros})
    return np.asarray(h, dtype=np.float32), np.asarray(c, dtype=np.float32)


class _StreamingStepper:
    """One LSTM cell step per sample, hidden and cell state passed through the graph."""

    def __init__(self, session: ort.InferenceSession, spec: GraphSpec, kind: str) -> None:
        self._session = session
        self._kind = kind
        self._rest_h, self._rest_c = rest_state(session, spec)
        self._in_lo, self._in_hi = spec.input_scaler.lo, spec.input_scaler.hi
        self._out_lo, self._out_hi = spec.output_scaler.lo, spec.output_scaler.hi
        self._x = np.zeros((1, 1, 1), dtype=np.float32)
        self._outputs = [OUTPUT_NAME, *STATE_OUTPUTS]
        self.reset()

    def reset(self) -> None:
        """The state at rest (:func:`rest_state`): every run starts from a vented muscle."""
        self._h = self._rest_h.copy()
        self._c = self._rest_c.copy()

    def step(self, value: float) -> float:
        """Input sample in SI, output sample in SI."""
        v = check_finite_step(value, self._kind)
        # Same operations, in the same order, as MinMaxScaler: stream and predict agree bitwise.
        self._x[0, 0, 0] = 2.0 * (v - self._in_lo) / (self._in_hi - self._in_lo) - 1.0
        y, self._h, self._c = self._session.run(
            self._outputs, {INPUT_NAME: self._x, STATE_INPUTS[0]: self._h, STATE_INPUTS[1]: self._c}
        )
        return (float(y[0, 0, 0]) + 1.0) * 0.5 * (self._out_hi - self._out_lo) + self._out_lo


class _WindowedStepper:
    """The thesis's window: the last ``window_samples`` inputs rerun through the LSTM each tick."""

    def __init__(self, session: ort.InferenceSession, spec: GraphSpec, kind: str) -> None:
        self._session = session
        self._kind = kind
        self._n = spec.window_samples
        self._in_lo, self._in_hi = spec.input_scaler.lo, spec.input_scaler.hi
        self._out_lo, self._out_hi = spec.output_scaler.lo, spec.output_scaler.hi
        self._rest = float(spec.input_scaler.transform(0.0))
        # Every sample is written twice, n apart, so the current window is always one
        # contiguous slice: no copy and no allocation per tick.
        self._buffer = np.empty(2 * self._n, dtype=np.float32)
        self._outputs = [OUTPUT_NAME]
        self.reset()

    def reset(self) -> None:
        """Fill the window with the input at rest (the thesis's left padding)."""
        self._buffer[:] = self._rest
        self._pos = 0

    def step(self, value: float) -> float:
        """Input sample in SI, output sample in SI."""
        v = check_finite_step(value, self._kind)
        x = np.float32(2.0 * (v - self._in_lo) / (self._in_hi - self._in_lo) - 1.0)
        p = self._pos
        self._buffer[p] = x
        self._buffer[p + self._n] = x
        window = self._buffer[p + 1 : p + 1 + self._n].reshape(1, self._n, 1)
        self._pos = (p + 1) % self._n
        (y,) = self._session.run(self._outputs, {INPUT_NAME: window})
        return (float(y[0, 0]) + 1.0) * 0.5 * (self._out_hi - self._out_lo) + self._out_lo


class _LSTMBase(Model):
    """Shared implementation of :class:`LSTMModel` and :class:`CLSTMModel`.

    Every argument is a field of :class:`LSTMSettings` (see there); ``None`` takes the kind's
    default from ``kind_defaults``, anything else the dataclass default.

    Attributes:
        config: The validated settings.
        preview_samples: How far ahead the input is read [samples] (0: none).
        onnx_model_: The fitted graph, serialised (what ``model.onnx`` holds).
        input_scaler_: Eq. 7.9 range of the input (SI), fitted on the training data.
        output_scaler_: Eq. 7.9 range of the output (SI), fitted on the training data.
    """

    kind_defaults: ClassVar[Mapping[str, Any]]
    requirement: ClassVar[DataRequirement] = DataRequirement(
        min_samples=5_000,
        why=(
            "An LSTM needs several loading and unloading cycles (at least 20 s at 250 Hz), "
            "of which 30% is held out for validation."
        ),
    )

    onnx_model_: bytes
    input_scaler_: MinMaxScaler
    output_scaler_: MinMaxScaler

    def __init__(
        self,
        *,
        form: Form | None = None,
        hidden_size: int | None = None,
        num_layers: int | None = None,
        window_samples: int | None = None,
        preview_samples: int | None = None,
        learning_rate: float | None = None,
        final_learning_rate: float | None = None,
        batch_size: int | None = None,
        chunk_samples: int | None = None,
        window_stride: int | None = None,
        max_epochs: int | None = None,
        patience_epochs: int | None = None,
        time_budget_s: float | None = None,
        validation_fraction: float | None = None,
        validation_split: ValidationSplit | None = None,
        input_noise_si: float | None = None,
        input_smoothing_hz: float | None = None,
        rest_weight: float | None = None,
        grad_clip_norm: float | None = None,
        seed: int | None = None,
        num_threads: int | None = None,
    ) -> None:
        # Explicit keywords (not **kwargs) so that `catheter-lab models` can list them.
        given = {k: v for k, v in locals().items() if k != "self"}
        chosen = {**self.kind_defaults, **{k: v for k, v in given.items() if v is not None}}
        if self.direction == "forward" and chosen.get("preview_samples", 0):
            raise ParameterError(
                f"{self.kind}: preview_samples is for the inverse model (a compensator knows "
                "its plan ahead); a forward model must stay causal in its input"
            )
        self.config = LSTMSettings(**chosen)
        self.preview_samples = self.config.preview_samples
        self._session: ort.InferenceSession | None = None
        self._spec: GraphSpec | None = None

    # -- fitting ------------------------------------------------------------------------------
    def fit(
        self,
        train: Sequence[Recording],
        validation: Sequence[Recording] = (),
        *,
        progress: bool = True,
    ) -> Self:
        """Train with torch (imported here only) and keep the exported ONNX graph.

        Args:
            train: Training recordings at one sample rate. Without ``validation``, a share
                (``validation_fraction``) is held out as ``validation_split`` says.
            validation: Recordings for early stopping; when given, all of ``train`` trains.
            progress: Show a tqdm bar per epoch.

        Raises:
            InsufficientDataError: Too little data; the message says how much more.
            RateMismatchError: The recordings differ in sample rate.
        """
        self._prepare(train, validation)
        shortest = min(len(r) for r in [*train, *validation])
        if shortest <= self.config.preview_samples + 1:
            raise ModelError(
                f"{self.kind}: a recording of {shortest} samples is too short for "
                f"preview_samples={self.config.preview_samples}"
            )
        from catheter_models.models import lstm_train

        result = lstm_train.train(
            self.kind,
            self.direction,
            self.config,
            train,
            validation,
            progress=progress,
        )
        self._set_graph(result.onnx_model)
        self.fit_report_ = result.report
        return self

    @classmethod
    def from_graph(cls, onnx_model: bytes, rate_hz: float) -> Self:
        """A fitted model from a graph exported by :mod:`~catheter_models.models.lstm_train`.

        The network's shape, form, preview and normalisation come from the graph's metadata;
        training settings take their defaults.

        Args:
            onnx_model: The serialised graph.
            rate_hz: Sample rate the graph was trained at [Hz].

        Raises:
            ModelError: Not such a graph, or one of another kind.
        """
        _, spec = open_session(onnx_model)
        if spec.kind != cls.kind:
            raise ModelError(f"the graph is a {spec.kind!r} model, not {cls.kind!r}")
        model = cls(
            form=spec.form,
            hidden_size=spec.hidden_size,
            num_layers=spec.num_layers,
            window_samples=spec.window_samples,
            preview_samples=spec.preview_samples,
        )
        model._set_graph(onnx_model)
        if not (math.isfinite(rate_hz) and rate_hz > 0.0):
            raise ParameterError(f"rate_hz must be finite and > 0, got {rate_hz!r}")
        model.rate_hz_ = float(rate_hz)
        return model

    # -- inference ----------------------------------------------------------------------------
    def predict(self, input_si: npt.ArrayLike) -> FloatArray:
        """Run a whole input signal from rest; SI in, SI out, same length.

        With a preview of L samples the network is fed the input L samples ahead, and the
        signal's last value is held past its end.

        Raises:
            SignalError: The input is not 1-D or has a non-finite sample.
            NotFittedError: Before fit or load.
        """
        x = as_input(input_si, f"{self.kind} input")
        session, spec = self._fitted()
        if x.size == 0:
            return np.zeros(0)
        x = read_ahead(x, spec.preview_samples)
        x_norm = spec.input_scaler.transform(x).astype(np.float32)
        if spec.form == "streaming":
            h0, c0 = rest_state(session, spec)
            y, _, _ = session.run(
                None,
                {INPUT_NAME: x_norm.reshape(-1, 1, 1), STATE_INPUTS[0]: h0, STATE_INPUTS[1]: c0},
            )
        else:
            n = spec.window_samples
            rest = np.float32(spec.input_scaler.transform(0.0))
            padded = np.concatenate([np.full(n - 1, rest, dtype=np.float32), x_norm])
            windows = np.lib.stride_tricks.sliding_window_view(padded, n)
            parts = []
            for i in range(0, x.size, _PREDICT_BATCH_WINDOWS):
                batch = np.ascontiguousarray(windows[i : i + _PREDICT_BATCH_WINDOWS])
                parts.append(session.run([OUTPUT_NAME], {INPUT_NAME: batch[:, :, None]})[0])
            y = np.concatenate(parts)
        return spec.output_scaler.inverse(np.asarray(y, dtype=np.float64).reshape(-1))

    def stream(self) -> Stream:
        """A stateful stepper at rest; with a preview, ``step`` takes the input L samples ahead.

        Raises:
            NotFittedError: Before fit or load.
        """
        session, spec = self._fitted()
        if spec.form == "streaming":
            return _StreamingStepper(session, spec, self.kind)
        return _WindowedStepper(session, spec, self.kind)

    # -- persistence --------------------------------------------------------------------------
    def save(
        self,
        path: Path | str,
        training: Sequence[Recording] = (),
        metrics: Mapping[str, Any] | None = None,
    ) -> Manifest:
        """Write the model directory; the manifest also says how the node must drive the graph.

        Besides the common entries, ``metrics`` gets ``form``, ``preview_samples`` (the node
        feeds the set-point that many ticks ahead), ``preview_s`` and ``onnx`` (the graph's
        inputs, outputs and state shape).
        """
        _, spec = self._fitted()
        rate = self.fitted_rate_hz
        if spec.form == "streaming":
            state = [spec.num_layers, 1, spec.hidden_size]
            io: dict[str, Any] = {
                "inputs": {INPUT_NAME: ["time", 1, 1], **dict.fromkeys(STATE_INPUTS, state)},
                "outputs": {OUTPUT_NAME: ["time", 1, 1], **dict.fromkeys(STATE_OUTPUTS, state)},
                "initial_state": "zeros (the catheter at rest)",
            }
        else:
            io = {
                "inputs": {INPUT_NAME: ["batch", spec.window_samples, 1]},
                "outputs": {OUTPUT_NAME: ["batch", 1]},
                "padding": "the input at rest (SI zero), normalised",
            }
        extra = {
            "form": spec.form,
            "preview_samples": spec.preview_samples,
            "preview_s": spec.preview_samples / rate,
            "onnx": io,
        }
        return super().save(path, training, {**extra, **dict(metrics or {})})

    def _payload(self) -> dict[str, bytes]:
        self._fitted()
        return {ONNX_FILE: self.onnx_model_}

    def _settings(self) -> dict[str, Any]:
        return asdict(self.config)

    def _normalization(self) -> dict[str, Any]:
        _, spec = self._fitted()
        inputs, outputs = self.signals()
        (in_name, in_unit), (out_name, out_unit) = (
            next(iter(inputs.items())),
            next(iter(outputs.items())),
        )
        return {
            "equation": "thesis eq. 7.9: x_norm = 2 (x - lo) / (hi - lo) - 1, inverted on output",
            "applied": "outside the ONNX graph, by the caller",
            "input": {"signal": in_name, "unit": in_unit, **spec.input_scaler.to_dict()},
            "output": {"signal": out_name, "unit": out_unit, **spec.output_scaler.to_dict()},
        }

    @classmethod
    def _from_payload(cls, manifest: Manifest, payload: Mapping[str, bytes]) -> Self:
        try:
            onnx_bytes = payload[ONNX_FILE]
        except KeyError:
            raise ModelDirError(f"{cls.kind} model directory lacks {ONNX_FILE!r}") from None
        raw_settings = manifest.metrics.get("settings")
        if not isinstance(raw_settings, Mapping):
            raise ModelError(f"{cls.kind}: manifest metrics lack the model's 'settings'")
        model = cls(**asdict(LSTMSettings.from_dict(raw_settings)))
        model._set_graph(onnx_bytes)
        _, spec = model._fitted()
        norm = manifest.normalization
        try:
            manifest_in = MinMaxScaler.from_dict(norm["input"])
            manifest_out = MinMaxScaler.from_dict(norm["output"])
        except (KeyError, TypeError):
            raise ModelError(
                f"{cls.kind}: manifest normalization lacks 'input'/'output' ranges"
            ) from None
        if manifest_in != spec.input_scaler or manifest_out != spec.output_scaler:
            raise ModelError(
                f"{cls.kind}: manifest normalization (input {manifest_in}, output {manifest_out}) "
                f"differs from the hashed graph's (input {spec.input_scaler}, output "
                f"{spec.output_scaler}); the manifest was edited, refusing to load"
            )
        return model

    # -- internals ----------------------------------------------------------------------------
    def _set_graph(self, onnx_bytes: bytes) -> None:
        """Open ``onnx_bytes`` and check that it is this kind's graph with these settings."""
        session, spec = open_session(onnx_bytes)
        s = self.config
        expected = (self.kind, s.form, s.hidden_size, s.num_layers, s.preview_samples)
        found = (spec.kind, spec.form, spec.hidden_size, spec.num_layers, spec.preview_samples)
        if expected != found or (s.form == "windowed" and spec.window_samples != s.window_samples):
            raise ModelError(
                f"{ONNX_FILE} is a {spec.kind} {spec.form} graph with {spec.num_layers}x"
                f"{spec.hidden_size} units, window {spec.window_samples}, preview "
                f"{spec.preview_samples}; the settings ask for a {self.kind} {s.form} graph with "
                f"{s.num_layers}x{s.hidden_size}, window {s.window_samples}, preview "
                f"{s.preview_samples}"
            )
        self.onnx_model_ = onnx_bytes
        self.input_scaler_ = spec.input_scaler
        self.output_scaler_ = spec.output_scaler
        self._session, self._spec = session, spec

    def _fitted(self) -> tuple[ort.InferenceSession, GraphSpec]:
        if self._session is None or self._spec is None:
            raise NotFittedError(f"{self.kind} model is not fitted: call fit() or load() first")
        return self._session, self._spec


class LSTMModel(_LSTMBase):
    """Thesis ch. 7: valve pressure [Pa] -> bend angle [rad], 2 x 64 LSTM and a linear head.

    Takes the keyword arguments of :class:`_LSTMBase` (the fields of :class:`LSTMSettings`);
    ``hidden_size`` defaults to the thesis's 64.
    """

    kind: ClassVar[str] = "lstm"
    direction: ClassVar[Direction] = "forward"
    kind_defaults: ClassVar[Mapping[str, Any]] = {"hidden_size": 64}


class CLSTMModel(_LSTMBase):
    """Thesis ch. 10: desired bend [rad] -> valve pressure [Pa], 2 x 128 LSTM; a compensator.

    Trained on measured bend (input) and commanded pressure (target), it is run on the desired
    bend. Its stream is the compensator the node hosts.

    Takes the keyword arguments of :class:`_LSTMBase` (the fields of :class:`LSTMSettings`);
    the defaults are the thesis's 2 x 128 network with the training settings measured best
    here (``kind_defaults``).
    """

    kind: ClassVar[str] = "clstm"
    direction: ClassVar[Direction] = "inverse"
    kind_defaults: ClassVar[Mapping[str, Any]] = {"hidden_size": 128}


__all__ = [
    "FORMS",
    "ONNX_FILE",
    "CLSTMModel",
    "GraphSpec",
    "LSTMModel",
    "LSTMSettings",
    "open_session",
    "session_options",
]
