"""Compensators the node can host, chosen by name, and the models shipped with the package.

``none`` is the static inverse of the quasi-static curve (no hysteresis compensation), the
baseline. ``idrdpi`` and ``clstm`` are the thesis's compensators: any inverse model
directory written by ``catheter-lab train`` (hash-checked on load); the c-LSTM runs on ONNX
Runtime, so the node never imports torch.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from catheter_control.control_core import StaticInverseCompensator, StreamingCompensator
from catheter_models.errors import ParameterError
from catheter_models.feedback import GAINS_FILE, FeedbackGains, PIDFeedback
from catheter_models.models.base import Stream
from catheter_models.static_map import StaticMap

COMPENSATORS = ("none", "idrdpi", "clstm")
DEFAULT_COMPENSATOR = "clstm"
"""The thesis's best compensator (Tables 11.1-11.4), and ours on the simulated rig."""
SHIPPED = {"none": "static_map", "idrdpi": "idrdpi", "clstm": "clstm"}
"""The model directory shipped for each compensator (fitted on the simulated rig)."""
FEEDBACKS = ("none", "pi")
"""Feedback on the measured bend the node can run beside its compensator."""
SHIPPED_GAINS = "feedback"
"""Directory of the shipped feedback gains (tuned on the simulated rig's recorded steps)."""


COMPENSATOR_OF_KIND = {"static_map": "none", "idrdpi": "idrdpi", "clstm": "clstm"}
"""Model kinds (a manifest's ``kind``) that are compensators, and the compensator each runs as:
the inverse models, and the quasi-static curve whose inverse ``none`` is."""


def compensator_of_model_dir(model_dir: str) -> str:
    """The compensator a model directory holds, from its manifest's kind (hash-checked).

    Raises:
        ParameterError: the directory holds a model that is not a compensator (a forward
            model, named by its kind).
        ModelDirError: the directory is missing, malformed, or fails its hash check.
    """
    from catheter_models.model_dir import read_model_dir

    kind = read_model_dir(Path(model_dir))[0].kind
    if kind in COMPENSATOR_OF_KIND:
        return COMPENSATOR_OF_KIND[kind]
    what = f"a {kind!r} model"
    from catheter_models.models import MODEL_KINDS, model_class

    if kind in MODEL_KINDS and model_class(kind).direction == "forward":
        what = f"a {kind!r} forward model (angle from pressure)"
    raise ParameterError(
        f"{model_dir} holds {what}, not a compensator; a compensator's model directory holds "
        f"one of {', '.join(sorted(COMPENSATOR_OF_KIND))} (catheter-lab train idrdpi|clstm)"
    )


def resolve_compensator(kind: str | None, model_dir: str) -> str:
    """The compensator to run: ``kind`` if given, else the model directory's, else the default.

    With both, the directory's manifest must agree with ``kind``: a c-LSTM directory run as
    ``idrdpi`` is refused here with both named, before anything starts.

    Raises:
        ParameterError: unknown ``kind``, a directory that is not a compensator, or one whose
            kind contradicts ``kind``.
        ModelDirError: the directory is missing, malformed, or fails its hash check.
    """
    if kind is not None and kind not in COMPENSATORS:
        raise ParameterError(f"unknown compensator {kind!r}; available: {', '.join(COMPENSATORS)}")
    if not model_dir:
        return kind or DEFAULT_COMPENSATOR
    held = compensator_of_model_dir(model_dir)
    if kind is not None and kind != held:
        raise ParameterError(
            f"compensator {kind!r} was asked for, but {model_dir} holds the {held!r} compensator "
            f"(its manifest's kind); leave the compensator out to run {held!r}, or give a "
            f"{kind!r} model directory"
        )
    return held


COMMISSIONED_FILE = "commissioned.json"
"""Written by ``commission`` into the model directory it chose: how to run it (its feedback)."""


def resolve_feedback(kind: str | None, model_dir: str) -> str:
    """The feedback to run: ``kind`` if given, else what ``commission`` ran the model with.

    A model directory that ``commission`` wrote carries ``commissioned.json``; its feedback
    (with the ``feedback.json`` beside it) is how the model was verified, so a directory given
    alone runs that way. Anything else runs without feedback unless asked.

    Raises:
        ParameterError: unknown ``kind``, or a ``commissioned.json`` that is not one.
    """
    import json

    if kind is not None:
        if kind not in FEEDBACKS:
            raise ParameterError(f"unknown feedback {kind!r}; available: {', '.join(FEEDBACKS)}")
        return kind
    path = Path(model_dir) / COMMISSIONED_FILE if model_dir else None
    if path is None or not path.exists():
        return "none"
    try:
        held = json.loads(path.read_text())["feedback"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ParameterError(f"{path} is not a commissioning record: {exc!r}") from None
    if held not in FEEDBACKS:
        raise ParameterError(f"{path} names feedback {held!r}; available: {', '.join(FEEDBACKS)}")
    return str(held)


def shipped_model_dir(name: str = "static_map") -> Path:
    """Directory of a model shipped inside this package (fitted on the simulated rig)."""
    return Path(str(resources.files("catheter_control") / "data" / name))


class ModelCompensator:
    """An inverse model's stream as the node's compensator.

    Args:
        stream: The model's stateful stepper (desired angle [rad] in, pressure [Pa] out).
        preview_s: How far ahead the model reads the plan [s].
        sample_period_s: The period the model was fitted at, which it must be stepped at [s].
        label: What the node reports it runs.
    """

    def __init__(
        self, stream: Stream, preview_s: float, sample_period_s: float, label: str
    ) -> None:
        self._stream = stream
        self.preview_s = preview_s
        self.sample_period_s: float | None = sample_period_s
        self.label = label

    def reset(self) -> None:
        """Back to rest: a new run starts from a vented muscle."""
        self._stream.reset()

    def step(self, angle_desired_rad: float) -> float:
        """Pressure command [Pa] for the (previewed) desired bend."""
        return float(self._stream.step(angle_desired_rad))


def load_compensator(kind: str, model_dir: str) -> StreamingCompensator:
    """Build the named compensator from a model directory ('' = the shipped one).

    A model is stepped at the rate it was fitted at whatever the control rate
    (:class:`~catheter_control.control_core.ControlCore` interpolates between its samples).

    Raises:
        ParameterError: Unknown kind, or a model of another kind or direction.
        ModelDirError: The directory is missing, malformed, or fails its hash check.
    """
    if kind not in COMPENSATORS:
        raise ParameterError(f"unknown compensator {kind!r}; available: {', '.join(COMPENSATORS)}")
    path = Path(model_dir) if model_dir else shipped_model_dir(SHIPPED[kind])
    if kind == "none":
        return StaticInverseCompensator(StaticMap.load(path))
    from catheter_models.models import model_class

    model = model_class(kind).load(path)
    if model.direction != "inverse":
        raise ParameterError(f"{path} holds a {model.kind} forward model, not a compensator")
    rate_hz = model.fitted_rate_hz
    return ModelCompensator(
        model.stream(), model.preview_samples / rate_hz, 1.0 / rate_hz, f"{kind} ({path})"
    )


def load_feedback(kind: str, gains_path: str, model_dir: str, rate_hz: float) -> PIDFeedback | None:
    """The feedback the node runs: None for ``none``, else PI with gains from a file.

    ``gains_path`` '' takes ``feedback.json`` from ``model_dir``, or the shipped gains when
    the model is the shipped one (tuned on the simulated rig: a real rig needs its own,
    ``catheter-lab tune``).

    The file is checked as :mod:`catheter_models.feedback.seal` says: sealed by
    ``catheter-lab tune`` (an edited or unsealed file is refused, with how to re-tune or
    reseal it), its gains within the range its tuning recorded, its authority and authority
    timeout within the contract's envelope. ``-p feedback_gains:=...`` and bringup's
    ``--feedback-gains`` name a file, so they pass the same checks.

    Raises:
        ParameterError: Unknown kind, a missing or malformed gains file, or a gain out of
            range (a negative gain, a sign error, is refused here, before anything moves).
        FeedbackFileError: the file fails its seal, its tuned range or the envelope (every
            problem named).
    """
    if kind not in FEEDBACKS:
        raise ParameterError(f"unknown feedback {kind!r}; available: {', '.join(FEEDBACKS)}")
    if kind == "none":
        return None
    if gains_path:
        path = Path(gains_path)
    elif model_dir:
        path = Path(model_dir) / GAINS_FILE
    else:
        path = shipped_model_dir(SHIPPED_GAINS) / GAINS_FILE
    return PIDFeedback(FeedbackGains.load(path), rate_hz)
