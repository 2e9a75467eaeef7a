"""Compensators the node can host, chosen by name, and the models shipped with the package.

``none`` is the static inverse of the quasi-static curve (no hysteresis compensation), the
baseline. ``idrdpi`` and ``clstm`` are the thesis's compensators: any inverse model
directory written by ``catheter-lab train`` (hash-checked on load); the c-LSTM runs on ONNX
Runtime, so the node never imports torch. ``greybox`` is the lab's explained model run
backwards (:mod:`catheter_models.models.greybox_inverse`): the model directory that
``catheter-lab explain``, ``add`` or ``core`` wrote; no model of it is shipped.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from catheter_control.control_core import StaticInverseCompensator, StreamingCompensator
from catheter_models.contract import CONTROL_RATE_HZ, MAX_PRESSURE_PA
from catheter_models.errors import ParameterError
from catheter_models.feedback import GAINS_FILE, FeedbackGains, PIDFeedback
from catheter_models.models.base import Stream
from catheter_models.shaping import SHAPERS, InputShaper, ShaperStream
from catheter_models.static_map import StaticMap

COMPENSATORS = ("none", "idrdpi", "clstm", "greybox")
DEFAULT_COMPENSATOR = "clstm"
"""The thesis's best compensator (Tables 11.1-11.4), and ours on the simulated rig."""
SHIPPED = {"none": "static_map", "idrdpi": "idrdpi", "clstm": "clstm"}
"""The model directory shipped for each compensator (fitted on the simulated rig); a grey box
is the user's own catheter explained, so none is shipped for ``greybox``."""
FEEDBACKS = ("none", "pi")
"""Feedback on the measured bend the node can run beside its compensator."""
SHIPPED_GAINS = "feedback"
"""Directory of the shipped feedback gains (tuned on the simulated rig's recorded steps)."""


NO_SHIPPED_GREYBOX = (
    "compensator 'greybox' needs the model directory that catheter-lab explain, add or core "
    "wrote (model_dir): no grey box is shipped, it is your catheter's own"
)

COMPENSATOR_OF_KIND = {
    "static_map": "none",
    "idrdpi": "idrdpi",
    "clstm": "clstm",
    "greybox": "greybox",
}
"""Model kinds (a manifest's ``kind``) that are compensators, and the compensator each runs as:
the inverse models, the quasi-static curve whose inverse ``none`` is, and the lab's grey box
whose inverse ``greybox`` is."""


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
    if kind == "greybox" and not model_dir:
        raise ParameterError(NO_SHIPPED_GREYBOX)  # before anything starts, not at configure
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


def _commissioned(model_dir: str, key: str) -> object | None:
    """``key`` of the ``commissioned.json`` in ``model_dir``, or None when there is none.

    Raises:
        ParameterError: a ``commissioned.json`` that is not one.
    """
    import json

    path = Path(model_dir) / COMMISSIONED_FILE if model_dir else None
    if path is None or not path.exists():
        return None
    try:
        record = json.loads(path.read_text())
        if not isinstance(record, dict) or "feedback" not in record:
            raise KeyError("feedback")
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ParameterError(f"{path} is not a commissioning record: {exc!r}") from None
    return record.get(key)


def _resolve_choice(
    kind: str | None, model_dir: str, key: str, choices: tuple[str, ...], what: str
) -> str:
    """``kind`` if given, else ``commissioned.json``'s ``key``, else ``none``.

    Raises:
        ParameterError: ``kind`` or the record's choice is not one of ``choices``.
    """
    if kind is not None:
        if kind not in choices:
            raise ParameterError(f"unknown {what} {kind!r}; available: {', '.join(choices)}")
        return kind
    held = _commissioned(model_dir, key)
    if held is None:
        return "none"
    if held not in choices:
        raise ParameterError(
            f"{Path(model_dir) / COMMISSIONED_FILE} names {what} {held!r}; "
            f"available: {', '.join(choices)}"
        )
    return str(held)


def resolve_shaping(kind: str | None, model_dir: str) -> str:
    """The feedforward shaping to run: ``kind`` if given, else what ``commission`` chose.

    Raises:
        ParameterError: unknown ``kind``, or a ``commissioned.json`` naming an unknown one.
    """
    return _resolve_choice(kind, model_dir, "feedforward_shaping", SHAPERS, "feedforward shaping")


def resolve_feedback(kind: str | None, model_dir: str) -> str:
    """The feedback to run: ``kind`` if given, else what ``commission`` ran the model with.

    A model directory that ``commission`` wrote carries ``commissioned.json``; its feedback
    (with the ``feedback.json`` beside it) is how the model was verified, so a directory given
    alone runs that way. Anything else runs without feedback unless asked.

    Raises:
        ParameterError: unknown ``kind``, or a ``commissioned.json`` that is not one.
    """
    return _resolve_choice(kind, model_dir, "feedback", FEEDBACKS, "feedback")


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


def load_compensator(
    kind: str, model_dir: str, *, max_pressure_pa: float = MAX_PRESSURE_PA
) -> StreamingCompensator:
    """Build the named compensator from a model directory ('' = the shipped one).

    A model is stepped at the rate it was fitted at whatever the control rate
    (:class:`~catheter_control.control_core.ControlCore` interpolates between its samples).

    Raises:
        ParameterError: Unknown kind, or a model of another kind or direction.
        ModelDirError: The directory is missing, malformed, or fails its hash check.
    """
    if kind not in COMPENSATORS:
        raise ParameterError(f"unknown compensator {kind!r}; available: {', '.join(COMPENSATORS)}")
    if kind == "greybox":
        # The chain's inverse keeps the plant's state as the model sees it: it must know the
        # clamp the node puts around its command.
        return load_greybox(model_dir, max_pressure_pa)
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


def load_greybox(model_dir: str, max_pressure_pa: float = MAX_PRESSURE_PA) -> ModelCompensator:
    """The grey box in ``model_dir`` run backwards, reading the plan as far ahead as it needs.

    Raises:
        ParameterError: no model directory (none is shipped), a model that is not a grey box,
            a block without an inverse, or a core whose fitted law is not invertible sample
            by sample (each named, with the number).
        ModelDirError: the directory is missing, malformed, or fails its hash check.
    """
    if not model_dir:
        raise ParameterError(NO_SHIPPED_GREYBOX)
    from catheter_models.models.greybox import GreyBox
    from catheter_models.models.greybox_inverse import GreyBoxInverse

    model = GreyBox.load(Path(model_dir))
    inverse = GreyBoxInverse(model, max_pressure_pa=max_pressure_pa)
    return ModelCompensator(
        inverse,
        inverse.preview_s,
        inverse.sample_period_s,
        f"greybox {' -> '.join(inverse.chain)} ({model_dir})",
    )


class ShapedCompensator:
    """A compensator whose pressure is input-shaped so it does not ring the tip.

    The inner compensator reads the plan the shaper's mean delay earlier than it would alone
    (its own preview plus the shaper's), so the shaped pressure arrives on time
    (:mod:`catheter_models.shaping`). A stateless inner map is stepped at the contract's
    control rate: the shaper needs a fixed grid.
    """

    def __init__(self, inner: StreamingCompensator, shaper: InputShaper) -> None:
        self.inner = inner
        self.shaper = shaper
        self.sample_period_s: float | None = inner.sample_period_s or 1.0 / CONTROL_RATE_HZ
        self.preview_s = inner.preview_s + shaper.mean_delay_s
        self._stream = ShaperStream(shaper, self.sample_period_s)
        self.label = f"{getattr(inner, 'label', type(inner).__name__)}, {shaper.describe()}"

    def reset(self) -> None:
        """Back to rest, the shaper's memory too."""
        self.inner.reset()
        self._stream.reset()

    def step(self, angle_desired_rad: float) -> float:
        """The inner compensator's pressure for the (earlier read) bend, shaped."""
        return self._stream.step(self.inner.step(angle_desired_rad))


def gains_file(gains_path: str, model_dir: str) -> Path:
    """The ``feedback.json`` in force: ``gains_path``, else the model directory's, else shipped."""
    if gains_path:
        return Path(gains_path)
    if model_dir:
        return Path(model_dir) / GAINS_FILE
    return shipped_model_dir(SHIPPED_GAINS) / GAINS_FILE


def shaper_for(kind: str, gains_path: str, model_dir: str) -> InputShaper | None:
    """The input shaper ``kind`` asks for (None for ``none``), designed on the tuned loop.

    The tip's mode comes from the loop that ``catheter-lab tune`` identified, recorded in the
    sealed ``feedback.json`` in force (as :func:`load_feedback` finds it), so the shaper and
    the feedback are designed on the same identified loop and an edited mode is refused by
    the seal. Launchers call it before anything starts; the node at configure.

    Raises:
        ParameterError: unknown kind, a gains file that is missing or malformed, or a loop
            with no tip resonance.
        FeedbackFileError: the file fails its seal, its tuned range or the envelope.
    """
    if kind not in SHAPERS:
        raise ParameterError(
            f"unknown feedforward shaping {kind!r}; available: {', '.join(SHAPERS)}"
        )
    if kind == "none":
        return None
    path = gains_file(gains_path, model_dir)
    return InputShaper.of_loop(kind, FeedbackGains.load(path).tuning.get("loop", {}), str(path))


def load_shaping(
    kind: str, compensator: StreamingCompensator, gains_path: str, model_dir: str
) -> StreamingCompensator:
    """``compensator`` with the feedforward shaping ``kind`` around it (``none``: as it is).

    Raises:
        ParameterError, FeedbackFileError: as :func:`shaper_for`.
    """
    shaper = shaper_for(kind, gains_path, model_dir)
    return compensator if shaper is None else ShapedCompensator(compensator, shaper)


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
    return PIDFeedback(FeedbackGains.load(gains_file(gains_path, model_dir)), rate_hz)
