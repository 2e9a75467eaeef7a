"""Train the LSTM and c-LSTM with torch and export them to ONNX (``dynamo=False``).

Imported only by :meth:`catheter_models.models.lstm._LSTMBase.fit` and by tests: inference
never needs torch.

Two network forms, one per inference form of :mod:`catheter_models.models.lstm`:

* :class:`StreamingNet` runs a whole sequence from a given state and returns the new state.
  It is trained on whole recordings with truncated back-propagation through time: every batch
  holds several recordings side by side, each is cut into ``chunk_samples`` chunks, and the
  state is carried (detached) from chunk to chunk, so the network sees exactly what it will
  see at run time (one long sequence from rest) while gradients stay short and cheap.
* :class:`WindowedNet` is the thesis's: the last 50 samples, left-padded with the input at
  rest, give one output. It is trained on every ``window_stride``-th window, with the phase of
  the stride drawn anew each epoch so that over the epochs every window is seen.

The 70/30 split is never by random samples (neighbouring samples are nearly equal, so that
would validate on the training data): either whole recordings are held out, evenly spaced
in the order given (``validation_split="recordings"``), or the last 30% of every recording
(``validation_split="time"``; the held-out part is scored after running the recording from
its start, so the state is warmed up as at run time).

Loss is the thesis's L2 loss, on normalised outputs (eq. 7.9). Adam with a cosine learning
rate schedule that reaches ``final_learning_rate`` at ``max_epochs`` or at the wall-time
budget, whichever comes first; early stopping keeps the epoch with the lowest validation
loss.
"""

from __future__ import annotations

import copy
import io
import math
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import onnx
import torch
from scipy.signal import butter, sosfiltfilt
from torch import nn
from tqdm import tqdm

from catheter_models.errors import ParameterError
from catheter_models.models.base import (
    Direction,
    FitReport,
    FloatArray,
    InsufficientDataError,
    MinMaxScaler,
    Recording,
    paired_ahead,
)
from catheter_models.models.lstm_graph import (
    INPUT_NAME,
    METADATA_KEY,
    OUTPUT_NAME,
    STATE_INPUTS,
    STATE_OUTPUTS,
    GraphSpec,
    LSTMSettings,
)

ONNX_OPSET = 17
"""ONNX opset of the exported graphs (ONNX Runtime >= 1.14 runs it)."""

_VALIDATION_BATCH_WINDOWS = 4096
_REST_FRACTION = 0.01
"""An input within this share of its range from the training minimum is "at rest"."""


class StreamingNet(nn.Module):
    """Stacked LSTM and a linear head, state in and out: ``(x, h0, c0) -> (y, hn, cn)``.

    Shapes (sequence first): ``x`` [T, B, 1], ``h0``/``c0`` [layers, B, hidden],
    ``y`` [T, B, 1]. All values normalised (eq. 7.9).
    """

    def __init__(self, hidden_size: int, num_layers: int) -> None:
        super().__init__()
        self.hidden_size = hidden_size
        self.num_layers = num_layers
        self.lstm = nn.LSTM(1, hidden_size, num_layers)
        self.head = nn.Linear(hidden_size, 1)

    def forward(
        self, x: torch.Tensor, h0: torch.Tensor, c0: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """One run over ``x`` from state ``(h0, c0)``."""
        out, (hn, cn) = self.lstm(x, (h0, c0))
        return self.head(out), hn, cn

    def zero_state(self, batch: int) -> tuple[torch.Tensor, torch.Tensor]:
        """The state at rest for ``batch`` sequences."""
        shape = (self.num_layers, batch, self.hidden_size)
        return torch.zeros(shape), torch.zeros(shape)


class WindowedNet(nn.Module):
    """The thesis's network: a window ``x`` [B, W, 1] -> the output at its last sample [B, 1]."""

    def __init__(self, hidden_size: int, num_layers: int) -> None:
        super().__init__()
        self.hidden_size = hidden_size
        self.num_layers = num_layers
        self.lstm = nn.LSTM(1, hidden_size, num_layers, batch_first=True)
        self.head = nn.Linear(hidden_size, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Each window from zero state; the head reads the last step's hidden output."""
        out, _ = self.lstm(x)
        y: torch.Tensor = self.head(out[:, -1, :])
        return y


def export_onnx(network: StreamingNet | WindowedNet, spec: GraphSpec) -> bytes:
    """Export with the TorchScript exporter (``dynamo=False``) and write ``spec`` as metadata.

    The streaming graph has a dynamic sequence length, batch 1 (the node runs one catheter):
    ``x`` [T, 1, 1], ``h0``/``c0`` [layers, 1, hidden] -> ``y`` [T, 1, 1], ``hn``, ``cn``.
    The windowed graph has a dynamic batch: ``x`` [B, W, 1] -> ``y`` [B, 1].
    """
    net = copy.deepcopy(network).cpu().eval()
    buffer = io.BytesIO()
    args: tuple[torch.Tensor, ...]
    if isinstance(net, StreamingNet):
        h0, c0 = net.zero_state(1)
        args = (torch.zeros(4, 1, 1), h0, c0)
        input_names = [INPUT_NAME, *STATE_INPUTS]
        output_names = [OUTPUT_NAME, *STATE_OUTPUTS]
        dynamic_axes = {INPUT_NAME: {0: "time"}, OUTPUT_NAME: {0: "time"}}
    else:
        args = (torch.zeros(2, spec.window_samples, 1),)
        input_names, output_names = [INPUT_NAME], [OUTPUT_NAME]
        dynamic_axes = {INPUT_NAME: {0: "batch"}, OUTPUT_NAME: {0: "batch"}}
    with warnings.catch_warnings():
        # The TorchScript exporter is chosen on purpose: it writes nn.LSTM as one ONNX LSTM
        # node that ONNX Runtime runs as a fused kernel. Its deprecation notice and the
        # tracer's notes on nn.LSTM's Python-side shape checks are expected, not news.
        warnings.filterwarnings("ignore", category=DeprecationWarning, module=r"torch\.")
        warnings.filterwarnings("ignore", category=torch.jit.TracerWarning)  # type: ignore[attr-defined]
        warnings.filterwarnings("ignore", message=r"Exporting a model to ONNX with a batch_size")
        warnings.filterwarnings("ignore", message=r"You are using the legacy TorchScript")
        torch.onnx.export(
            net,
            args,
            buffer,  # type: ignore[arg-type]  # the TorchScript exporter writes to file objects
            dynamo=False,
            input_names=input_names,
            output_names=output_names,
            dynamic_axes=dynamic_axes,
            opset_version=ONNX_OPSET,
        )
    model = onnx.load_from_string(buffer.getvalue())
    entry = model.metadata_props.add()
    entry.key = METADATA_KEY
    entry.value = spec.to_json()
    model.producer_name = "catheter_models.models.lstm_train"
    onnx.checker.check_model(model)
    data: bytes = model.SerializeToString()
    return data


@dataclass(frozen=True)
class TrainResult:
    """What :func:`train` returns.

    Attributes:
        onnx_model: The exported graph of the best epoch, with its metadata.
        network: The torch network of the best epoch (for checks against the graph).
        spec: What the graph is (also in its metadata).
        report: Loss curves and what stopped training.
    """

    onnx_model: bytes
    network: StreamingNet | WindowedNet
    spec: GraphSpec
    report: FitReport


@dataclass(frozen=True)
class _Sequence:
    """One recording as the network sees it: SI input (preview-shifted) and target.

    ``scored_from`` is the first sample that counts in the loss (the held-out tail of a
    time split is scored after a warm-up over the recording's start).
    """

    name: str
    x_si: FloatArray
    y_si: FloatArray
    scored_from: int = 0


def _sequence(
    rec: Recording, direction: Direction, preview: int, smoothing_hz: float = 0.0
) -> _Sequence:
    x, y = rec.io(direction)
    if smoothing_hz > 0.0:
        nyquist_hz = 0.5 * rec.rate_hz
        if smoothing_hz >= nyquist_hz:
            raise ParameterError(
                f"input_smoothing_hz={smoothing_hz:g} must be below the Nyquist frequency "
                f"of {rec.name!r} ({nyquist_hz:g} Hz)"
            )
        # Forward and backward: no phase shift, so the smoothed input does not lag.
        sos = butter(2, smoothing_hz, fs=rec.rate_hz, output="sos")
        x = np.asarray(sosfiltfilt(sos, x), dtype=np.float64)
    x, y = paired_ahead(x, y, preview)  # the input leads: angle[k + L] with pressure[k]
    return _Sequence(rec.name, x, y)


def split(
    train: Sequence[Recording],
    validation: Sequence[Recording],
    direction: Direction,
    settings: LSTMSettings,
) -> tuple[list[_Sequence], list[_Sequence], str]:
    """Training and validation sequences, and a one-line account of the split.

    Raises:
        InsufficientDataError: A split by recordings with a single recording.
    """
    lead, fc = settings.preview_samples, settings.input_smoothing_hz
    train_seqs = [_sequence(r, direction, lead, fc) for r in train]
    if validation:
        val_seqs = [_sequence(r, direction, lead, fc) for r in validation]
        return train_seqs, val_seqs, f"given: {len(train)} train, {len(validation)} validation"
    if settings.validation_split == "recordings":
        n = len(train_seqs)
        if n < 2:
            raise InsufficientDataError(
                "a split by whole recordings needs at least 2 recordings, 1 given: record "
                "another one, or set validation_split='time'"
            )
        n_val = min(n - 1, max(1, round(settings.validation_fraction * n)))
        # Evenly spaced, not random: recordings come in a designed order (the thesis sets
        # nest frequency and decay), so every part of the design keeps most of its
        # recordings for training. A random draw once held out 7 of the 10 slowest signals.
        spacing = n / n_val
        shift = settings.seed % max(1, int(spacing))
        val_idx = {(int((j + 0.5) * spacing) + shift) % n for j in range(n_val)}
        held = [s for i, s in enumerate(train_seqs) if i in val_idx]
        kept = [s for i, s in enumerate(train_seqs) if i not in val_idx]
        names = ", ".join(s.name for s in held)
        return kept, held, f"recordings: {len(kept)} train, {n_val} validation ({names})"
    kept, held = [], []
    for s in train_seqs:
        cut = round((1.0 - settings.validation_fraction) * s.x_si.size)
        kept.append(_Sequence(s.name, s.x_si[:cut], s.y_si[:cut]))
        held.append(_Sequence(s.name, s.x_si, s.y_si, scored_from=cut))
    share = round(100 * settings.validation_fraction)
    return kept, held, f"time: the last {share}% of each of {len(kept)} recordings"


def _loss_weights(x_norm: FloatArray, rest_weight: float) -> FloatArray:
    """Per-sample loss weights: ``rest_weight`` where the normalised input is at rest."""
    return np.where(x_norm <= -1.0 + 2.0 * _REST_FRACTION, rest_weight, 1.0)


def _padded(
    seqs: Sequence[_Sequence],
    x_scaler: MinMaxScaler,
    y_scaler: MinMaxScaler,
    rest_weight: float,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Sequences side by side, normalised: x, y [T, N, 1] and the loss weights [T, N, 1].

    Shorter sequences are padded at their end, where nothing they produce reaches a scored
    sample; padding and unscored samples weigh 0.
    """
    t_max = max(s.x_si.size for s in seqs)
    x = np.zeros((t_max, len(seqs), 1), dtype=np.float32)
    y = np.zeros_like(x)
    mask = np.zeros_like(x)
    for j, s in enumerate(seqs):
        n = s.x_si.size
        x_norm = x_scaler.transform(s.x_si)
        x[:n, j, 0] = x_norm
        y[:n, j, 0] = y_scaler.transform(s.y_si)
        mask[s.scored_from : n, j, 0] = _loss_weights(x_norm[s.scored_from :], rest_weight)
    return torch.from_numpy(x), torch.from_numpy(y), torch.from_numpy(mask)


def _masked_mse(out: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    return ((out - target) ** 2 * mask).sum() / mask.sum().clamp(min=1e-12)


class _Schedule:
    """Cosine learning rate over the nearer of ``max_epochs`` and the wall-time budget."""

    def __init__(self, settings: LSTMSettings, start_s: float) -> None:
        self.settings = settings
        self.start_s = start_s

    def elapsed_s(self) -> float:
        return time.monotonic() - self.start_s

    def out_of_time(self) -> bool:
        return self.elapsed_s() >= self.settings.time_budget_s

    def apply(self, optimizer: torch.optim.Optimizer, epochs_done: float) -> None:
        s = self.settings
        progress = min(1.0, max(epochs_done / s.max_epochs, self.elapsed_s() / s.time_budget_s))
        lr = s.final_learning_rate + 0.5 * (s.learning_rate - s.final_learning_rate) * (
            1.0 + math.cos(math.pi * progress)
        )
        for group in optimizer.param_groups:
            group["lr"] = lr


def _noise_std(settings: LSTMSettings, x_scaler: MinMaxScaler) -> float:
    """``input_noise_si`` in normalised units."""
    return 2.0 * settings.input_noise_si / (x_scaler.hi - x_scaler.lo)


class _StreamingTrainer:
    """Truncated BPTT over whole recordings, many recordings per batch."""

    def __init__(
        self,
        net: StreamingNet,
        *,
        settings: LSTMSettings,
        train: tuple[torch.Tensor, torch.Tensor, torch.Tensor],
        val: tuple[torch.Tensor, torch.Tensor, torch.Tensor],
        noise_std: float,
        rng: np.random.Generator,
        generator: torch.Generator,
    ) -> None:
        self.net, self.s = net, settings
        self.train, self.val = train, val
        self.noise_std, self.rng, self.gen = noise_std, rng, generator
        self.n_train = train[0].shape[1]
        t_len = train[0].shape[0]
        self.updates_per_epoch = math.ceil(self.n_train / settings.batch_size) * math.ceil(
            t_len / settings.chunk_samples
        )

    def epoch(
        self, optimizer: torch.optim.Optimizer, schedule: _Schedule, epoch: int
    ) -> tuple[float, bool]:
        """One pass; returns mean training loss and whether the time budget ran out."""
        self.net.train()
        x_all, y_all, m_all = self.train
        order = self.rng.permutation(self.n_train)
        total, count, updates = 0.0, 0, 0
        for b in range(0, self.n_train, self.s.batch_size):
            idx = torch.from_numpy(order[b : b + self.s.batch_size])
            x, y, m = x_all[:, idx], y_all[:, idx], m_all[:, idx]
            if self.noise_std > 0.0:
                x = x + self.noise_std * torch.randn(x.shape, generator=self.gen)
            h, c = self.net.zero_state(idx.numel())
            for t0 in range(0, x.shape[0], self.s.chunk_samples):
                t1 = t0 + self.s.chunk_samples
                if m[t0:t1].sum() == 0:
                    break  # only padding left in this batch
                schedule.apply(optimizer, epoch + updates / self.updates_per_epoch)
                out, h, c = self.net(x[t0:t1], h, c)
                loss = _masked_mse(out, y[t0:t1], m[t0:t1])
                optimizer.zero_grad(set_to_none=True)
                loss.backward()
                nn.utils.clip_grad_norm_(self.net.parameters(), self.s.grad_clip_norm)
                optimizer.step()
                h, c = h.detach(), c.detach()
                total += float(loss.detach())
                count += 1
                updates += 1
                if schedule.out_of_time():
                    return total / max(count, 1), True
        return total / max(count, 1), False

    @torch.no_grad()
    def validation_loss(self) -> float:
        """Whole validation recordings from rest, as :meth:`LSTMModel.predict` runs them."""
        self.net.eval()
        x, y, m = self.val
        h, c = self.net.zero_state(x.shape[1])
        out, _, _ = self.net(x, h, c)
        return float(_masked_mse(out, y, m))


class _WindowedTrainer:
    """The thesis's windows, every ``window_stride``-th one, in shuffled batches."""

    def __init__(
        self,
        net: WindowedNet,
        *,
        settings: LSTMSettings,
        train: Sequence[_Sequence],
        val: Sequence[_Sequence],
        x_scaler: MinMaxScaler,
        y_scaler: MinMaxScaler,
        noise_std: float,
        rng: np.random.Generator,
        generator: torch.Generator,
    ) -> None:
        self.net, self.s = net, settings
        self.noise_std, self.rng, self.gen = noise_std, rng, generator
        rest = float(x_scaler.transform(0.0))
        self.train_x, self.train_y, self.train_w, self.train_ends = self._flatten(
            train, x_scaler, y_scaler, rest
        )
        self.val_x, self.val_y, self.val_w, val_ends = self._flatten(val, x_scaler, y_scaler, rest)
        self.val_ends = val_ends[:: settings.window_stride]
        self.offsets = torch.arange(settings.window_samples) - (settings.window_samples - 1)
        n_windows = math.ceil(self.train_ends.numel() / settings.window_stride)
        self.updates_per_epoch = math.ceil(n_windows / settings.batch_size)

    def _flatten(
        self,
        seqs: Sequence[_Sequence],
        x_scaler: MinMaxScaler,
        y_scaler: MinMaxScaler,
        rest: float,
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """All sequences in one padded strip: inputs, targets, loss weights, scored window ends.

        Each sequence is preceded by ``window - 1`` samples of the input at rest, so the window
        ending at any of its samples never reaches into the previous sequence.
        """
        pad = self.s.window_samples - 1
        xs, ys, ws, ends = [], [], [], []
        cursor = 0
        for s in seqs:
            n = s.x_si.size
            x_norm = x_scaler.transform(s.x_si)
            xs += [np.full(pad, rest), x_norm]
            ys += [np.zeros(pad), y_scaler.transform(s.y_si)]
            ws += [np.zeros(pad), _loss_weights(x_norm, self.s.rest_weight)]
            ends.append(cursor + pad + np.arange(s.scored_from, n))
            cursor += pad + n
        return (
            torch.from_numpy(np.concatenate(xs).astype(np.float32)),
            torch.from_numpy(np.concatenate(ys).astype(np.float32)),
            torch.from_numpy(np.concatenate(ws).astype(np.float32)),
            torch.from_numpy(np.concatenate(ends)),
        )

    def epoch(
        self, optimizer: torch.optim.Optimizer, schedule: _Schedule, epoch: int
    ) -> tuple[float, bool]:
        """One pass over a fresh stride phase; returns mean loss and whether time ran out."""
        self.net.train()
        phase = int(self.rng.integers(self.s.window_stride))
        ends = self.train_ends[phase :: self.s.window_stride]
        ends = ends[torch.from_numpy(self.rng.permutation(ends.numel()))]
        x_strip = self.train_x
        if self.noise_std > 0.0:
            x_strip = x_strip + self.noise_std * torch.randn(x_strip.shape, generator=self.gen)
        total, count = 0.0, 0
        for b in range(0, ends.numel(), self.s.batch_size):
            end = ends[b : b + self.s.batch_size]
            schedule.apply(optimizer, epoch + count / self.updates_per_epoch)
            out = self.net(x_strip[end[:, None] + self.offsets][:, :, None])
            loss = _masked_mse(out[:, 0], self.train_y[end], self.train_w[end])
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            nn.utils.clip_grad_norm_(self.net.parameters(), self.s.grad_clip_norm)
            optimizer.step()
            total += float(loss.detach())
            count += 1
            if schedule.out_of_time():
                return total / count, True
        return total / max(count, 1), False

    @torch.no_grad()
    def validation_loss(self) -> float:
        """Weighted mean squared error over every ``window_stride``-th validation window."""
        self.net.eval()
        total, weight = 0.0, 0.0
        for b in range(0, self.val_ends.numel(), _VALIDATION_BATCH_WINDOWS):
            end = self.val_ends[b : b + _VALIDATION_BATCH_WINDOWS]
            out = self.net(self.val_x[end[:, None] + self.offsets][:, :, None])
            w = self.val_w[end]
            total += float(((out[:, 0] - self.val_y[end]) ** 2 * w).sum())
            weight += float(w.sum())
        return total / max(weight, 1e-12)


def train(
    kind: str,
    direction: Direction,
    settings: LSTMSettings,
    train_recordings: Sequence[Recording],
    validation_recordings: Sequence[Recording] = (),
    *,
    progress: bool = True,
) -> TrainResult:
    """Train a network of ``settings.form`` and export the best epoch to ONNX.

    Args:
        kind: ``"lstm"`` or ``"clstm"`` (written into the graph's metadata).
        direction: ``"forward"`` (pressure -> angle) or ``"inverse"`` (angle -> pressure).
        settings: Network shape and training settings.
        train_recordings: Training data, one sample rate (checked by the caller).
        validation_recordings: Held-out data; if empty, split from ``train_recordings``.
        progress: Show a tqdm bar, one tick per epoch.

    Returns:
        The ONNX graph, the torch network and a report.
    """
    started = time.monotonic()
    s = settings
    train_seqs, val_seqs, split_note = split(train_recordings, validation_recordings, direction, s)
    x_scaler = MinMaxScaler.fit(np.concatenate([q.x_si for q in train_seqs]))
    y_scaler = MinMaxScaler.fit(np.concatenate([q.y_si for q in train_seqs]))
    noise_std = _noise_std(s, x_scaler)

    threads_before = torch.get_num_threads()
    torch.set_num_threads(s.num_threads)
    try:
        torch.manual_seed(s.seed)
        generator = torch.Generator().manual_seed(s.seed)
        rng = np.random.default_rng(s.seed)
        net: StreamingNet | WindowedNet
        trainer: _StreamingTrainer | _WindowedTrainer
        if s.form == "streaming":
            net = StreamingNet(s.hidden_size, s.num_layers)
            trainer = _StreamingTrainer(
                net,
                settings=s,
                train=_padded(train_seqs, x_scaler, y_scaler, s.rest_weight),
                val=_padded(val_seqs, x_scaler, y_scaler, s.rest_weight),
                noise_std=noise_std,
                rng=rng,
                generator=generator,
            )
        else:
            net = WindowedNet(s.hidden_size, s.num_layers)
            trainer = _WindowedTrainer(
                net,
                settings=s,
                train=train_seqs,
                val=val_seqs,
                x_scaler=x_scaler,
                y_scaler=y_scaler,
                noise_std=noise_std,
                rng=rng,
                generator=generator,
            )
        optimizer = torch.optim.Adam(net.parameters(), lr=s.learning_rate)
        schedule = _Schedule(s, time.monotonic())
        report = FitReport()
        best_loss, best_epoch = math.inf, -1
        best_state = copy.deepcopy(net.state_dict())
        stopped = "max_epochs"
        bar = tqdm(
            total=s.max_epochs, desc=f"{kind} ({s.form})", unit="epoch", disable=not progress
        )
        try:
            for epoch in range(s.max_epochs):
                train_loss, out_of_time = trainer.epoch(optimizer, schedule, epoch)
                val_loss = trainer.validation_loss()
                report.train_loss.append(train_loss)
                report.validation_loss.append(val_loss)
                if val_loss < best_loss:
                    best_loss, best_epoch = val_loss, epoch
                    best_state = copy.deepcopy(net.state_dict())
                bar.update(1)
                bar.set_postfix(train=f"{train_loss:.2e}", val=f"{val_loss:.2e}", best=best_epoch)
                if out_of_time:
                    stopped = f"time budget of {s.time_budget_s:g} s"
                    break
                if epoch - best_epoch >= s.patience_epochs:
                    stopped = f"no validation improvement for {s.patience_epochs} epochs"
                    break
        finally:
            bar.close()
        net.load_state_dict(best_state)
        net.eval()
    finally:
        torch.set_num_threads(threads_before)

    spec = GraphSpec(
        kind=kind,
        form=s.form,
        hidden_size=s.hidden_size,
        num_layers=s.num_layers,
        window_samples=s.window_samples,
        preview_samples=s.preview_samples,
        input_scaler=x_scaler,
        output_scaler=y_scaler,
    )
    onnx_model = export_onnx(net, spec)
    half_range = 0.5 * (y_scaler.hi - y_scaler.lo)
    report.duration_s = time.monotonic() - started
    report.extra.update(
        {
            "loss": "mean squared error of the normalised output (eq. 7.9)",
            "epochs": len(report.train_loss),
            "best_epoch": best_epoch,
            "stopped_by": stopped,
            "validation_rmse_si": math.sqrt(best_loss) * half_range,
            "split": split_note,
            "train_samples": int(sum(q.x_si.size for q in train_seqs)),
            "torch_version": torch.__version__,
            "threads": s.num_threads,
        }
    )
    return TrainResult(onnx_model, net, spec, report)
