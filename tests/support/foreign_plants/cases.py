"""Cases for testing the lab on foreign plants: one training and one held-out recording.

A case is a plant variant, the effects hidden in it, and a seed. Its data are what a person
at a rig would record with the lab's protocol: about 5 minutes of training excitation (the
thesis's training sines, plateau signals with slow and fast ramps) played back to back as one
recording, and about 2 minutes of held-out excitation of other seeds (a chirp, plateaus, fast
steps, a descending sine), also as one recording. Signals are inputs, so they come from
``catheter_models.signals``; everything the bend does comes from the foreign plant.

Seeds below :data:`HELD_OUT_SEED0` are for development; cases from that seed on are the
held-out part that a method is not tuned on (benchmarks report the two apart).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

import numpy as np

from catheter_models.lab.signals import lab_spec
from catheter_models.models.base import Recording
from catheter_models.signals import SignalSpec, get_preset, training_set

from .base import Effect, FloatArray, ForeignPlant

RATE_HZ: Final = 250.0
HELD_OUT_SEED0: Final = 1000
_GAP_S: Final = 1.0
"""Vented pause between signals played back to back (the muscle empties, the tip rests)."""


def _signal_seed(seed: int, k: int) -> int:
    # Plateau generators take small integer seeds; keep every case's apart from the lab's own
    # (100-102, 998-999) and from each other.
    return 20_000 + 16 * seed + k


def training_specs(seed: int) -> list[SignalSpec]:
    """About 5 minutes: the thesis's 8 training sines and four plateau signals (two fast)."""
    specs: list[SignalSpec] = list(training_set())
    for k, fast in enumerate((False, True, False, True)):
        name = f"lab_{'steps' if fast else 'plateaus'}_{_signal_seed(seed, k)}"
        spec = lab_spec(name)
        assert spec is not None
        specs.append(spec)
    return specs


def test_specs(seed: int) -> list[SignalSpec]:
    """About 2 minutes: the up-chirp, plateaus, fast steps and the descending sine."""
    plateaus = lab_spec(f"lab_plateaus_{_signal_seed(seed, 8)}")
    steps = lab_spec(f"lab_steps_{_signal_seed(seed, 9)}")
    assert plateaus is not None and steps is not None
    return [
        get_preset("model_test_up_chirp"),
        plateaus,
        steps,
        dataclasses.replace(get_preset("model_test_descending_sine")),
    ]


def back_to_back(specs: Sequence[SignalSpec], rate_hz: float = RATE_HZ) -> FloatArray:
    """The signals played one after another, each followed by a vented pause."""
    gap = np.zeros(round(_GAP_S * rate_hz))
    parts: list[FloatArray] = []
    for spec in specs:
        parts += [np.asarray(spec.generate(rate_hz).values_si, dtype=float), gap]
    return np.concatenate(parts)


@dataclass(frozen=True)
class Case:
    """One test of the lab: the plant, what is hidden in it, and its data."""

    plant: ForeignPlant
    effects: tuple[Effect, ...]
    seed: int
    train: Recording
    test: Recording

    @property
    def held_out(self) -> bool:
        """Whether this case belongs to the held-out part (not looked at while tuning)."""
        return self.seed >= HELD_OUT_SEED0

    @property
    def label(self) -> str:
        """e.g. ``maxwell_slip/3 creep(...) seed 7``."""
        hidden = " + ".join(e.label() for e in self.effects) or "nothing"
        return f"{self.plant.name}/{self.plant.variant} {hidden} seed {self.seed}"


def make_case(plant: ForeignPlant, effects: Sequence[Effect], seed: int) -> Case:
    """Simulate the training and held-out recordings of one case."""
    recordings = []
    for part, specs, noise_seed in (
        ("train", training_specs(seed), 2 * seed),
        ("test", test_specs(seed), 2 * seed + 1),
    ):
        pressure = back_to_back(specs)
        angle = plant.simulate(pressure, RATE_HZ, tuple(effects), seed=noise_seed)
        recordings.append(
            Recording(
                name=f"{plant.name}_{part}_{seed}",
                rate_hz=RATE_HZ,
                pressure_pa=pressure,
                angle_rad=np.asarray(angle, dtype=float),
                source=f"foreign:{plant.name}/{plant.variant}:{part}",
            )
        )
    return Case(plant, tuple(effects), seed, recordings[0], recordings[1])


def draw_twin_case(plant_cls: type[ForeignPlant], names: Sequence[str], seed: int) -> Case:
    """A case whose catheter depends on the plant and ``seed`` alone, so that every case of
    one seed is the same catheter with the same signals and noise: the case with nothing
    hidden (``names`` empty) is the twin of each of them. Strengths are drawn by ``seed`` and
    ``names`` as in :func:`draw_case` (which draws the variant from the names too, and so
    has no twins; its cases are kept as they were for the earlier tables)."""
    variant_rng = np.random.default_rng([seed, *(ord(c) for c in plant_cls.name)])
    plant = plant_cls(variant=int(variant_rng.integers(0, 1_000)))
    rng = np.random.default_rng([seed, len(names), *(ord(c) for n in names for c in n)])
    return make_case(plant, [Effect.draw(n, rng) for n in names], seed)


def draw_case(plant_cls: type[ForeignPlant], names: Sequence[str], seed: int) -> Case:
    """A case with ``names`` hidden at strengths drawn from the real-rig ranges by ``seed``,
    on the plant variant ``seed`` draws too."""
    rng = np.random.default_rng([seed, len(names), *(ord(c) for n in names for c in n)])
    plant = plant_cls(variant=int(rng.integers(0, 1_000)))
    return make_case(plant, [Effect.draw(n, rng) for n in names], seed)
