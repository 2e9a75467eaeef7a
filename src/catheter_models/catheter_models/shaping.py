"""Input shaping of the feedforward: a pressure that does not ring a resonant tip.

A catheter tip with a lightly damped bending mode (``catheter-lab tune`` identifies it from
recorded steps: ``resonance_hz``, ``resonance_damping``) rings whenever the command has energy
near that mode. The hysteresis compensators make such energy at every reversal: the inverse of
a play operator turns the desired bend's smooth turn into a kink in the pressure. A smooth
desired bend therefore does not help (measured on a Bouc-Wen plant with a 4.5 Hz tip, damping
0.07: shaping the *desired bend* by the tip's inverse changed the tracking RMSE by 1 %), while
shaping the *pressure* does.

An input shaper convolves the command with a few impulses timed and sized so that the mode's
responses to them cancel (Singer and Seering, 1990). The ZVD shaper (zero vibration and zero
derivative) cancels the mode and is insensitive to a frequency error to first order: three
impulses at 0, half and one whole damped period. Its cost is delay, half a damped period on
average (about 110 ms for a 4.5 Hz tip); on its own that would lag the bend behind the plan.
The plan is known ahead, so the compensator reads it that much early (its ``preview_s``):
the shaped pressure then arrives on time, and only the feedback runs without preview.

Only the feedforward is shaped. Shaping the feedback's correction too would put the shaper's
delay inside the loop and cost it its margins.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from catheter_models.errors import ParameterError

SHAPERS = ("none", "zvd")
"""The feedforward shapings the compensator node can run."""

MAX_SHAPER_DELAY_S = 0.5
"""Longest mean delay a shaper may add [s]: a mode below ~1 Hz is not a tip mode but the
motion the catheter is asked for, and shaping it would smear the plan itself."""


@dataclass(frozen=True)
class InputShaper:
    """Impulses (times [s] from now, amplitudes summing to 1) the feedforward is convolved with.

    Attributes:
        times_s: impulse times, the first 0, increasing [s].
        amplitudes: impulse amplitudes, positive, summing to 1 (the static gain is kept).
        mode_hz: the mode it cancels [Hz] (for the record).
        mode_damping: that mode's damping ratio.
    """

    times_s: tuple[float, ...]
    amplitudes: tuple[float, ...]
    mode_hz: float
    mode_damping: float

    @classmethod
    def zvd(cls, mode_hz: float, damping: float) -> InputShaper:
        """The ZVD shaper of a mode at ``mode_hz`` with damping ratio ``damping``.

        Raises:
            ParameterError: a frequency or damping that is not a lightly damped mode, or a
                mode so slow its shaper would delay the plan by more than
                :data:`MAX_SHAPER_DELAY_S` on average.
        """
        if not (math.isfinite(mode_hz) and mode_hz > 0.0):
            raise ParameterError(f"shaper mode must be a frequency > 0 Hz, got {mode_hz!r}")
        if not (math.isfinite(damping) and 0.0 <= damping < 1.0):
            raise ParameterError(f"shaper mode damping must be in [0, 1), got {damping!r}")
        root = math.sqrt(1.0 - damping * damping)
        half_period_s = 0.5 / (mode_hz * root)
        k = math.exp(-damping * math.pi / root)
        norm = (1.0 + k) ** 2
        shaper = cls(
            times_s=(0.0, half_period_s, 2.0 * half_period_s),
            amplitudes=(1.0 / norm, 2.0 * k / norm, k * k / norm),
            mode_hz=float(mode_hz),
            mode_damping=float(damping),
        )
        if shaper.mean_delay_s > MAX_SHAPER_DELAY_S:
            raise ParameterError(
                f"a {mode_hz:.3g} Hz mode is too slow to shape: its ZVD shaper would delay the "
                f"feedforward by {shaper.mean_delay_s:.2f} s on average (limit "
                f"{MAX_SHAPER_DELAY_S} s, MAX_SHAPER_DELAY_S); that is the catheter's motion, "
                "not a tip ringing"
            )
        return shaper

    @classmethod
    def of_loop(cls, kind: str, loop: dict[str, Any], source: str) -> InputShaper | None:
        """The shaper ``kind`` for the loop that ``catheter-lab tune`` identified (None: none).

        ``loop`` is the ``tuning.loop`` record of a sealed ``feedback.json``; ``source`` names
        it in errors.

        Raises:
            ParameterError: unknown kind, or a loop with no tip resonance to shape.
        """
        if kind not in SHAPERS:
            raise ParameterError(
                f"unknown feedforward shaping {kind!r}; available: {', '.join(SHAPERS)}"
            )
        if kind == "none":
            return None
        try:
            mode_hz = float(loop["resonance_hz"])
            damping = float(loop["resonance_damping"])
        except (KeyError, TypeError, ValueError):
            raise ParameterError(
                f"{source} records no identified loop (tuning.loop with resonance_hz and "
                "resonance_damping); re-tune with catheter-lab tune"
            ) from None
        if not mode_hz > 0.0:
            raise ParameterError(
                f"feedforward shaping {kind!r} shapes a ringing tip, but the loop in {source} "
                "has none (catheter-lab tune found no resonance in its steps); run without it"
            )
        return cls.zvd(mode_hz, damping)

    @property
    def mean_delay_s(self) -> float:
        """The shaper's average delay [s]: how far ahead the compensator must read the plan."""
        return float(np.dot(self.times_s, self.amplitudes))

    def describe(self) -> str:
        """One line for a person."""
        return (
            f"ZVD shaper for the {self.mode_hz:.2f} Hz tip (damping {self.mode_damping:.3f}): "
            f"{len(self.times_s)} impulses over {self.times_s[-1] * 1e3:.0f} ms, plan read "
            f"{self.mean_delay_s * 1e3:.0f} ms ahead"
        )

    def taps(self, period_s: float) -> tuple[np.ndarray, np.ndarray]:
        """The shaper on a sample grid: integer delays [samples] and their weights.

        An impulse between two samples is split between them linearly, so the shaper's mean
        delay and static gain are exact on any grid.
        """
        if not (math.isfinite(period_s) and period_s > 0.0):
            raise ParameterError(f"shaper sample period must be > 0 s, got {period_s!r}")
        weights: dict[int, float] = {}
        for t_s, a in zip(self.times_s, self.amplitudes, strict=True):
            x = t_s / period_s
            k = math.floor(x)
            frac = x - k
            weights[k] = weights.get(k, 0.0) + a * (1.0 - frac)
            if frac > 0.0:
                weights[k + 1] = weights.get(k + 1, 0.0) + a * frac
        delays = np.array(sorted(weights), dtype=np.int64)
        return delays, np.array([weights[int(d)] for d in delays])


class ShaperStream:
    """An :class:`InputShaper` applied one sample at a time (a causal FIR on the samples).

    Before the first sample the input is taken to have been the first sample forever (a run
    starts at rest, at the first command), so the output starts with no jump.
    """

    def __init__(self, shaper: InputShaper, period_s: float) -> None:
        self.shaper = shaper
        self._delays, self._weights = shaper.taps(period_s)
        self._size = int(self._delays[-1]) + 1
        self._history: deque[float] = deque(maxlen=self._size)
        self._pairs = [(int(d), float(w)) for d, w in zip(self._delays, self._weights, strict=True)]

    def reset(self) -> None:
        """Forget the past: the next sample is the first."""
        self._history.clear()

    def step(self, value: float) -> float:
        """The shaped output for this sample's input ``value``."""
        history = self._history
        if not history:
            history.extend([value] * self._size)
        history.append(value)
        last = self._size - 1
        return sum(w * history[last - d] for d, w in self._pairs)
