"""A strong black-box reference: a recurrent network on top of the filter bank.

The filter bank (:class:`~catheter_models.lab.floors.FilterBankReference`) is linear in its
weights: it cannot learn a law of loops it has no column for, a gain that changes with the
pressure's direction, or dynamics that change with the bend. Whether a model's miss is
learnable at all from 5 minutes of data is only answered by a learner that is not limited so.
:class:`RecurrentReference` is the usual one in system identification: a GRU, trained to
convergence on the same training recordings, scored on the same held-out ones.

Protocol (what the system-identification benchmarks do, so that its number means something):

* **Inputs that carry memory and rate**: the pressure through play operators of thresholds
  spread over the valve's range (generic rate-independent memory, with no fitted weight),
  the pressure's rate, and the filter bank's prediction. The network learns the filter bank's
  residual; its readout starts at zero, so before training it *is* the filter bank.
* **A time-ordered validation part**: the last :attr:`validation_share` of every training
  recording. The filter bank is fitted on the part before it, so validation sees neither.
* **Early stopping** on the validation RMSE (after a warm-up from rest), **several starts**
  (the one with the lowest validation error is kept), truncated back-propagation through
  through time on random windows: each starts from a zero state, runs a burn-in that is
  not scored, then a scored chunk (the plays and the filter bank carry the long memory, so
  the network needs only the short one; many short windows give many updates per epoch).
* **Warm-up before scoring**: held-out RMSE is taken after :attr:`warmup_s` of each
  recording, run from rest (the state needs the time to settle; the bank's and the grey
  box's scores include it, which can only favour the network by the first seconds' share).

torch is imported when it is fitted, never at run time of the graph. Training is seconds to
minutes per start on one core (``bench/bench_lab_foreign.py`` reports it).
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Final

import numpy as np
import numpy.typing as npt

from catheter_models.errors import ParameterError
from catheter_models.hysteresis.operators import play
from catheter_models.lab.floors import FilterBankReference
from catheter_models.models.base import Recording
from catheter_models.units import pa_to_bar, rad_to_deg

if TYPE_CHECKING:
    import torch

FloatArray = npt.NDArray[np.float64]

PLAY_THRESHOLDS_BAR: Final = (0.0, 0.03, 0.07, 0.12, 0.2, 0.3, 0.45, 0.65)
"""Thresholds of the input plays [bar]: backlash-free to wider than the widest loop seen."""
RATE_SCALE_BAR_S: Final = 5.0
"""The pressure's rate is divided by this before it enters the network [bar/s]."""
OUTPUT_SCALE_DEG: Final = 30.0
"""The filter bank's prediction is divided by this before it enters the network [deg]."""
NAME: Final = "recurrent black box"


def _features(x_bar: FloatArray, rate_hz: float, bank_deg: FloatArray) -> FloatArray:
    """Plays, rate and the filter bank's prediction, one row per sample."""
    thresholds = np.asarray(PLAY_THRESHOLDS_BAR)
    x = np.ascontiguousarray(x_bar, dtype=np.float64)
    plays = np.zeros((x.size, thresholds.size))
    per_sample = np.ascontiguousarray(np.repeat(thresholds[None], x.size, 0))
    play(x, per_sample, np.zeros(thresholds.size), plays)
    rate = np.gradient(x) * rate_hz / RATE_SCALE_BAR_S
    return np.column_stack([plays, rate, bank_deg / OUTPUT_SCALE_DEG])


@dataclass
class StartReport:
    """One start of the training: where it stopped and its validation error."""

    seed: int
    epochs: int
    best_epoch: int
    validation_deg: float


@dataclass
class RecurrentReference:
    """A GRU that learns what the filter bank leaves (see module doc).

    Attributes:
        hidden: The GRU's state size.
        starts: Independent trainings; the lowest validation error is kept.
        max_epochs: Longest training of one start.
        patience: Epochs without a better validation error before a start stops.
        chunk_s: Scored part of a training window [s].
        burn_in_s: Unscored start of a training window, from a zero state [s].
        batch: Windows per update.
        updates_per_epoch: Updates between two validations.
        validation_share: Last share of every training recording held out for early stopping.
        warmup_s: Seconds from rest not scored (state settling).
        learning_rate: Adam's initial step; halved as a cosine over the epochs.
        seed: Seed of the first start (start k uses ``seed + k``).
    """

    hidden: int = 32
    starts: int = 3
    max_epochs: int = 60
    patience: int = 10
    chunk_s: float = 1.0
    burn_in_s: float = 0.5
    batch: int = 32
    updates_per_epoch: int = 40
    validation_share: float = 0.2
    warmup_s: float = 2.0
    learning_rate: float = 5e-3
    seed: int = 0
    report_: list[StartReport] = field(default_factory=list)
    rate_hz_: float = 0.0
    bank_: FilterBankReference | None = None
    state_: dict[str, Any] | None = None
    target_scale_deg_: float = 1.0

    def fit(self, train: Sequence[Recording], *, progress: bool = False) -> RecurrentReference:
        """Train on ``train`` (all at one sample rate); see the module doc for the protocol."""
        import torch

        if not train:
            raise ParameterError("the recurrent reference needs training recordings")
        rate_hz = train[0].rate_hz
        if any(r.rate_hz != rate_hz for r in train):
            raise ParameterError("the recurrent reference needs recordings at one sample rate")
        self.rate_hz_ = rate_hz
        cuts = [round((1.0 - self.validation_share) * r.pressure_pa.size) for r in train]
        fit_parts = [
            dataclasses.replace(r, pressure_pa=r.pressure_pa[:c], angle_rad=r.angle_rad[:c])
            for r, c in zip(train, cuts, strict=True)
        ]
        self.bank_ = FilterBankReference().fit(fit_parts)
        inputs, targets = [], []
        for r in train:
            x_bar = pa_to_bar(r.pressure_pa)
            bank = self.bank_.predict_deg(x_bar)
            inputs.append(_features(x_bar, rate_hz, bank).astype(np.float32))
            targets.append((rad_to_deg(r.angle_rad) - bank).astype(np.float32))
        scale = float(np.std(np.concatenate([t[:c] for t, c in zip(targets, cuts, strict=True)])))
        self.target_scale_deg_ = scale if scale > 0.0 else 1.0
        threads = torch.get_num_threads()
        torch.set_num_threads(1)
        try:
            best: tuple[float, dict[str, Any] | None] = (math.inf, None)
            self.report_ = []
            for k in range(self.starts):
                state, report = self._train_one(inputs, targets, cuts, self.seed + k, progress)
                self.report_.append(report)
                if report.validation_deg < best[0]:
                    best = (report.validation_deg, state)
            self.state_ = best[1]
        finally:
            torch.set_num_threads(threads)
        return self

    def _net(self, n_inputs: int) -> torch.nn.Module:
        from torch import nn

        class _GRU(nn.Module):
            def __init__(self, n_in: int, hidden: int) -> None:
                super().__init__()
                self.gru = nn.GRU(n_in, hidden, batch_first=True)
                self.out = nn.Linear(hidden, 1)
                # Readout at zero: before training the reference is the filter bank.
                nn.init.zeros_(self.out.weight)
                nn.init.zeros_(self.out.bias)

            def forward(
                self, x: torch.Tensor, h: torch.Tensor | None = None
            ) -> tuple[torch.Tensor, torch.Tensor]:
                o, h_new = self.gru(x, h)
                return self.out(o)[..., 0], h_new

        return _GRU(n_inputs, self.hidden)

    def _train_one(
        self,
        inputs: list[np.ndarray],
        targets: list[np.ndarray],
        cuts: list[int],
        seed: int,
        progress: bool,
    ) -> tuple[dict[str, Any], StartReport]:
        import torch

        torch.manual_seed(seed)
        rng = np.random.default_rng(seed)
        net = self._net(inputs[0].shape[1])  # each start its own initial weights (the seed)
        optimizer = torch.optim.Adam(net.parameters(), lr=self.learning_rate)
        schedule = torch.optim.lr_scheduler.CosineAnnealingLR(
            optimizer, self.max_epochs, eta_min=0.1 * self.learning_rate
        )
        burn = round(self.burn_in_s * self.rate_hz_)
        window = burn + max(10, round(self.chunk_s * self.rate_hz_))
        x_all, y_all = self._training_part(inputs, targets, cuts, window)
        # Epoch 0 is the filter bank itself (the readout starts at zero): never worse.
        best_deg, best_epoch = self._validation_deg(net, inputs, targets, cuts), 0
        best_state = copy.deepcopy(net.state_dict())
        epochs = 0
        label = f"recurrent reference, start {seed - self.seed + 1}"
        bar = _progress(progress, self.max_epochs, label)
        for epoch in range(1, self.max_epochs + 1):
            epochs = epoch
            net.train()
            for _ in range(self.updates_per_epoch):
                starts = rng.integers(0, x_all.shape[0] - window, self.batch)
                index = torch.from_numpy(starts[:, None] + np.arange(window)[None, :])
                out, _ = net(x_all[index])
                loss = torch.mean((out[:, burn:] - y_all[index][:, burn:]) ** 2)
                optimizer.zero_grad()
                loss.backward()
                torch.nn.utils.clip_grad_norm_(net.parameters(), 1.0)
                optimizer.step()
            schedule.step()
            val = self._validation_deg(net, inputs, targets, cuts)
            if bar is not None:
                bar.update(1)
                bar.set_postfix(validation_deg=f"{val:.3f}")
            if val < best_deg:
                best_deg, best_state, best_epoch = val, copy.deepcopy(net.state_dict()), epoch
            elif epoch - best_epoch >= self.patience:
                break
        if bar is not None:
            bar.close()
        return best_state, StartReport(seed, epochs, best_epoch, best_deg)

    def _training_part(
        self, inputs: list[np.ndarray], targets: list[np.ndarray], cuts: list[int], window: int
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """The training parts, end to end, as tensors (targets scaled)."""
        import torch

        x = np.concatenate([i[:c] for i, c in zip(inputs, cuts, strict=True)])
        y = np.concatenate([t[:c] for t, c in zip(targets, cuts, strict=True)])
        if x.shape[0] < 10 * window:
            raise ParameterError(
                "the recurrent reference needs at least "
                f"{10 * window / self.rate_hz_ / (1.0 - self.validation_share):.0f} s "
                "of training data"
            )
        y_scaled = (y / self.target_scale_deg_).astype(np.float32)
        return torch.from_numpy(np.ascontiguousarray(x)), torch.from_numpy(y_scaled)

    def _validation_deg(
        self,
        net: torch.nn.Module,
        inputs: list[np.ndarray],
        targets: list[np.ndarray],
        cuts: list[int],
    ) -> float:
        """RMSE [deg] on the last part of every training recording, each run from rest."""
        errors = []
        for x, y, c in zip(inputs, targets, cuts, strict=True):
            residual = self._run(net, x)
            errors.append(residual[c:] - y[c:])
        err = np.concatenate(errors)
        return float(np.sqrt(np.mean(err**2))) if err.size else math.inf

    def _run(self, net: torch.nn.Module, x: np.ndarray) -> FloatArray:
        import torch

        net.eval()
        with torch.no_grad():
            out, _ = net(torch.from_numpy(np.ascontiguousarray(x, dtype=np.float32))[None])
        return np.asarray(out[0].numpy(), dtype=np.float64) * self.target_scale_deg_

    def predict_deg(self, x_bar: FloatArray) -> FloatArray:
        """Bend [deg] for pressure [bar], from rest."""
        import torch

        if self.bank_ is None or self.state_ is None:
            raise ParameterError("the recurrent reference is not fitted")
        bank = self.bank_.predict_deg(x_bar)
        features = _features(x_bar, self.rate_hz_, bank).astype(np.float32)
        threads = torch.get_num_threads()
        torch.set_num_threads(1)
        try:
            net = self._net(features.shape[1])
            net.load_state_dict(self.state_)
            return bank + self._run(net, features)
        finally:
            torch.set_num_threads(threads)

    def rmse_deg(self, recordings: Sequence[Recording]) -> float:
        """Pooled held-out RMSE [deg], each recording run from rest, its warm-up not scored."""
        skip = round(self.warmup_s * self.rate_hz_)
        err = np.concatenate(
            [
                (self.predict_deg(pa_to_bar(r.pressure_pa)) - rad_to_deg(r.angle_rad))[skip:]
                for r in recordings
            ]
        )
        return float(np.sqrt(np.mean(err**2)))


def _progress(on: bool, total: int, label: str) -> Any:
    if not on:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc=label, unit="epoch", leave=False)
