"""Score models the thesis's way: modelling on test signals, control with the plant in the loop.

``modelling_score``: a forward model predicts the bend for a recorded pressure signal
(Tables 8.1-8.4). ``tracking_score``: an inverse model runs as an open-loop feedforward
compensator, one sample at a time through its *stream* (as the compensator node runs it),
its commands limited as the node limits them, and the simulated plant answers
(Tables 11.1-11.4). Metrics are in SI (rad, or Pa for an inverse model's modelling score),
as everywhere in the stack; ``metrics.format("deg")`` prints them as the thesis does.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from catheter_models.contract import MAX_PRESSURE_PA, MAX_SLEW_PA_PER_S
from catheter_models.metrics import ErrorMetrics, compute_metrics
from catheter_models.models.base import FloatArray, Model, Recording, Stream
from catheter_models.plant import Plant, PlantConfig
from catheter_models.signals import SignalSpec, get_preset

# The compensator node's defaults (catheter_control.compensator_node): the same limits here
# keep a benchmark honest about what the node would have commanded. The ceiling is the
# contract's, which the node's default reads too.
DEFAULT_MAX_PRESSURE_PA = MAX_PRESSURE_PA
DEFAULT_MAX_SLEW_PA_PER_S = MAX_SLEW_PA_PER_S


@dataclass(frozen=True, eq=False)
class ModellingResult:
    """A forward model against a measured recording (angles in rad)."""

    recording: Recording
    predicted_rad: FloatArray
    metrics: ErrorMetrics


@dataclass(frozen=True, eq=False)
class TrackingResult:
    """An open-loop compensator on the plant.

    Attributes:
        trajectory: The preset's name.
        t_s: Sample times [s].
        desired_rad: Set-point [rad].
        command_pa: What the compensator commanded after limits [Pa gauge].
        measured_rad: The laser's angle [rad] (what the thesis scores).
        metrics: RMSE / MAE (max abs) / NRMSE of measured vs desired [rad].
    """

    trajectory: str
    t_s: FloatArray
    desired_rad: FloatArray
    command_pa: FloatArray
    measured_rad: FloatArray
    metrics: ErrorMetrics


def modelling_score(model: Model, recording: Recording) -> ModellingResult:
    """Predict ``recording``'s output from its input and score it in degrees."""
    predicted = model.predict_recording(recording)
    _, measured = recording.io(model.direction)
    metrics = compute_metrics(predicted, measured)
    return ModellingResult(recording, predicted, metrics)


def pooled_rmse(model: Model, recordings: Sequence[Recording]) -> float:
    """RMSE over every sample of ``recordings`` pooled, each predicted from rest (output SI).

    Pooled, not averaged per recording: a long recording counts for its length, as the
    lab's comparisons and its history score a model.
    """
    errors = [model.predict_recording(r) - r.io(model.direction)[1] for r in recordings]
    return float(np.sqrt(np.mean(np.concatenate(errors) ** 2)))


def run_compensator(
    stream: Stream,
    desired_rad: FloatArray,
    *,
    rate_hz: float,
    max_pressure_pa: float = DEFAULT_MAX_PRESSURE_PA,
    max_slew_pa_per_s: float = DEFAULT_MAX_SLEW_PA_PER_S,
    preview_samples: int = 0,
) -> FloatArray:
    """Step ``stream`` through ``desired_rad`` from rest, clamping and slew-limiting like the node.

    A non-finite output stops the run at zero pressure, as the node's ControlCore does. A
    compensator with a preview is fed the set-point ``preview_samples`` ahead (held at the
    plan's last value), as the node feeds it from the plan it knows in advance.
    """
    stream.reset()
    n = desired_rad.size
    out = np.zeros(n)
    last = 0.0
    step = max_slew_pa_per_s / rate_hz
    for k in range(n):
        target = stream.step(float(desired_rad[min(k + preview_samples, n - 1)]))
        if not np.isfinite(target):
            break
        target = min(max(target, 0.0), max_pressure_pa)
        last = min(max(target, last - step), last + step)
        out[k] = last
    return out


def lead_in(start_rad: float, rate_hz: float, approach_s: float, settle_s: float) -> FloatArray:
    """Set-points that bring the catheter from rest to a trajectory's first angle, then hold.

    A raised-cosine move over ``approach_s`` then ``settle_s`` at ``start_rad``: how a rig
    starts a trajectory that does not begin straight (thesis trajectory 2 begins at 8 deg).
    Without it the first tenth of a second is a step no compensator can follow, and it would
    dominate the score (the thesis's MAE of 1.54 deg on trajectory 2 shows its runs had none).
    """
    n_move = round(approach_s * rate_hz)
    n_hold = round(settle_s * rate_hz)
    shape = 0.5 - 0.5 * np.cos(np.pi * np.arange(1, n_move + 1) / max(n_move, 1))
    return np.concatenate([start_rad * shape, np.full(n_hold, start_rad)])


def track(
    stream: Stream,
    trajectory: SignalSpec | str,
    config: PlantConfig | None = None,
    *,
    preview_samples: int = 0,
    max_pressure_pa: float = DEFAULT_MAX_PRESSURE_PA,
    max_slew_pa_per_s: float = DEFAULT_MAX_SLEW_PA_PER_S,
    approach_s: float = 1.0,
    settle_s: float = 1.0,
) -> TrackingResult:
    """Follow a thesis trajectory open loop: a compensator's stream drives the simulated plant.

    The run starts from rest with a :func:`lead_in` to the trajectory's first angle; only the
    trajectory itself is scored (and returned), from its own t = 0.

    Args:
        stream: The compensator (desired angle [rad] in, pressure [Pa] out), stepped at the
            plant's sample rate.
        trajectory: An angle preset (``traj_*``) or its name.
        config: The plant; default: the thesis rig, seed 0.
        preview_samples: Feed the set-point this many samples ahead (the model's setting).
        max_pressure_pa: Command ceiling [Pa gauge], as the node's.
        max_slew_pa_per_s: Command slew limit [Pa/s], as the node's.
        approach_s: Duration of the move from rest to the first angle [s].
        settle_s: Hold at the first angle before the trajectory starts [s].
    """
    spec = get_preset(trajectory) if isinstance(trajectory, str) else trajectory
    config = config or PlantConfig.thesis_rig()
    rate_hz = float(config.rig["sample_rate_hz"])
    signal = spec.generate(rate_hz)
    desired = np.asarray(signal.values_si)
    before = lead_in(float(desired[0]), rate_hz, approach_s, settle_s)
    command = run_compensator(
        stream,
        np.concatenate([before, desired]),
        rate_hz=rate_hz,
        max_pressure_pa=max_pressure_pa,
        max_slew_pa_per_s=max_slew_pa_per_s,
        preview_samples=preview_samples,
    )
    out = Plant(config).simulate(command)
    measured = np.asarray(out.angle_rad)[before.size :]
    metrics = compute_metrics(measured, desired)
    return TrackingResult(
        spec.name, np.asarray(signal.t_s), desired, command[before.size :], measured, metrics
    )


def tracking_score(
    model: Model,
    trajectory: SignalSpec | str,
    config: PlantConfig | None = None,
    **limits: float,
) -> TrackingResult:
    """:func:`track` with an inverse model's stream and preview (Tables 11.1-11.4).

    Raises:
        ValueError: ``model`` is a forward model, or was fitted at another rate than the
            plant samples.
    """
    config = config or PlantConfig.thesis_rig()
    rate_hz = float(config.rig["sample_rate_hz"])
    if model.direction != "inverse":
        raise ValueError(f"{model.kind} is a forward model; tracking needs an inverse model")
    if abs(model.fitted_rate_hz - rate_hz) > 1e-9:
        msg = f"{model.kind} works at {model.fitted_rate_hz:g} Hz, the plant at {rate_hz:g} Hz"
        raise ValueError(msg)
    return track(
        model.stream(), trajectory, config, preview_samples=model.preview_samples, **limits
    )
