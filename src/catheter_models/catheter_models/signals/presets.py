"""The thesis's signals as named presets: training sets, modelling tests, control trajectories.

Each preset keeps the numbers the thesis prints (and a ``note`` where it has to deviate), so
this file is the table a reader compares with the thesis; it holds no equations and no
classes, only their settings and the registry that looks them up by name.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Final, Literal

from catheter_models.errors import SignalError

from .specs import ArbitrarySpec, ChirpSpec, DescendingSineSpec, SignalSpec

TRAINING_AMPLITUDE_BAR: Final = 1.5
TRAINING_DECAY_PER_S: Final = 0.15
TRAINING_FREQS_HZ: Final = (0.2, 0.4, 0.6, 0.8)
TRAINING_DURATION_S: Final = 13.4
CLSTM_DECAYS_PER_S: Final = (0.02, 0.05, 0.1, 0.15, 0.2)
CLSTM_DURATION_S: Final = 26.0
_BASELINE_FORMS: Final[tuple[tuple[Literal["zero", "nonzero"], str], ...]] = (
    ("zero", "4.1"),
    ("nonzero", "4.2"),
)


def _training_specs() -> tuple[DescendingSineSpec, ...]:
    specs = []
    for baseline, eq in _BASELINE_FORMS:
        for f_hz in TRAINING_FREQS_HZ:
            specs.append(
                DescendingSineSpec(
                    name=f"train_{baseline}_f{f_hz:g}",
                    kind="pressure",
                    amplitude=TRAINING_AMPLITUDE_BAR,
                    decay_per_s=TRAINING_DECAY_PER_S,
                    freq_hz=f_hz,
                    baseline=baseline,
                    duration_s=TRAINING_DURATION_S,
                    source=f"eq. {eq}, sec. 4.1.1 / 5.3.2 (DRDPI training set)",
                    note=(
                        "The thesis gives only the total, 26798 samples over 8 signals at "
                        "250 Hz; 13.4 s per signal is that total divided evenly."
                    ),
                )
            )
    return tuple(specs)


def _clstm_specs() -> tuple[DescendingSineSpec, ...]:
    specs = []
    for baseline, eq in _BASELINE_FORMS:
        for f_hz in TRAINING_FREQS_HZ:
            for tau in CLSTM_DECAYS_PER_S:
                specs.append(
                    DescendingSineSpec(
                        name=f"clstm_{baseline}_f{f_hz:g}_tau{tau:g}",
                        kind="pressure",
                        amplitude=TRAINING_AMPLITUDE_BAR,
                        decay_per_s=tau,
                        freq_hz=f_hz,
                        baseline=baseline,
                        duration_s=CLSTM_DURATION_S,
                        source=f"eq. {eq}, sec. 10.3.1 (c-LSTM training set)",
                        note=(
                            "The thesis gives only the total, 260269 samples over 40 groups "
                            "at 250 Hz; 26 s per group is that total divided evenly. A = 1.5 "
                            "bar is assumed as in sec. 4.1.1 (not restated in sec. 10.3.1)."
                        ),
                    )
                )
    return tuple(specs)


_MODEL_TEST_SPECS: Final[tuple[SignalSpec, ...]] = (
    DescendingSineSpec(
        name="model_test_descending_sine",
        kind="pressure",
        amplitude=1.5,
        decay_per_s=0.12,
        freq_hz=0.7,
        baseline="zero",
        duration_s=20.0,
        source="eq. 4.1, sec. 5.4.2 test 1 (fig. 5.6)",
        note="Duration not printed; 20 s covers the waves of fig. 5.6.",
    ),
    ChirpSpec(
        name="model_test_down_chirp",
        kind="pressure",
        amplitude=0.9,
        offset=1.2,
        freq_hz=0.7,
        decay_per_s=0.1,
        chirp_hz_per_s=-0.7 / (4.0 * 20.0),
        duration_s=20.0,
        source="eq. 5.16, sec. 5.4.2 test 2 (fig. 5.7)",
        note=(
            "Printed c = -0.1 makes the instantaneous frequency f + 2ct reach zero at 3.5 s, "
            "which cannot give the several waves of fig. 5.7. Used c = -f/(4T) = -0.00875 Hz/s "
            "with T = 20 s, so the frequency falls from 0.7 Hz to 0.35 Hz."
        ),
    ),
    ChirpSpec(
        name="model_test_up_chirp",
        kind="pressure",
        amplitude=0.6,
        freq_hz=0.3,
        decay_per_s=-0.05,
        chirp_hz_per_s=0.015,
        duration_s=18.0,
        source="eq. 5.17, sec. 5.4.2 test 3 (fig. 5.8)",
        note=(
            "Printed tau = 0.05, c = 0.15 pass 1 Hz (the studied band) at 2.3 s and peak at "
            "1.2 bar, which cannot give the ~21 deg range implied by table 8.3 (RMSE/NRMSE). "
            "Used tau = -0.05 (a growing, 'ascending' envelope), c = 0.015 Hz/s and T = 18 s: "
            "the frequency rises from 0.3 to 0.84 Hz and the peak stays below 3 bar."
        ),
    ),
    ArbitrarySpec(
        name="model_test_arbitrary_plateaus",
        kind="pressure",
        seed=5409,
        level_min=0.0,
        level_max=3.0,
        max_ramp_rate=6.0,
        duration_s=40.0,
        source="sec. 5.4.2 test 4 (fig. 5.9); no equation in the thesis",
        note=(
            "Designed: random levels in 0-3 bar, plateaus of 1-3 s, raised-cosine ramps of "
            "0.5-2 s capped at 6 bar/s (about the peak rate of test 1), fixed seed."
        ),
    ),
)

_TRAJECTORY_SPECS: Final[tuple[SignalSpec, ...]] = (
    ChirpSpec(
        name="traj_descending_sine",
        kind="angle",
        amplitude=10.0,
        freq_hz=0.3,
        decay_per_s=0.05,
        chirp_hz_per_s=0.0,
        duration_s=20.0,
        source="eq. 9.22, sec. 9.3.1 / 10.3.2 trajectory 1 (figs. 9.4, 10.5)",
        note=(
            "A is not printed; A = 10 deg fits the ~18.5 deg range that table 11.1's "
            "RMSE/NRMSE implies. Duration not printed; 20 s."
        ),
    ),
    ChirpSpec(
        name="traj_down_chirp",
        kind="angle",
        amplitude=10.0,
        offset=8.0,
        freq_hz=0.5,
        decay_per_s=0.05,
        chirp_hz_per_s=-0.5 / (4.0 * 20.0),
        duration_s=20.0,
        source="eq. 9.23, sec. 9.3.1 / 10.3.2 trajectory 2 (figs. 9.6, 10.7)",
        note=(
            "c is not printed; used c = -f/(4T) = -0.00625 Hz/s with T = 20 s, so the "
            "frequency falls from 0.5 Hz to 0.25 Hz, as in model test 2."
        ),
    ),
    ChirpSpec(
        name="traj_up_chirp",
        kind="angle",
        amplitude=6.0,
        freq_hz=0.3,
        decay_per_s=-0.02,
        chirp_hz_per_s=0.005,
        duration_s=20.0,
        source="eq. 9.24, sec. 9.3.1 / 10.3.2 trajectory 3 (figs. 9.8, 10.9)",
        note="Duration not printed; 20 s.",
    ),
    ArbitrarySpec(
        name="traj_arbitrary_small_variations",
        kind="angle",
        seed=9310,
        level_min=0.0,
        level_max=25.0,
        max_ramp_rate=40.0,
        variation_amplitude=(0.5, 1.5),
        variation_freq_hz=(1.0, 2.0),
        variation_probability=0.5,
        duration_s=40.0,
        source="sec. 9.3.1 / 10.3.2 trajectory 4 (figs. 9.10, 10.11); no equation in the thesis",
        note=(
            "Designed: random levels in 0-25 deg, plateaus of 1-3 s, raised-cosine ramps of "
            "0.5-2 s capped at 40 deg/s (about the peak rate of trajectories 1-3); about half "
            "the plateaus carry +-0.5-1.5 deg variations at 1-2 Hz, like compensating a heart "
            "beat. Fixed seed."
        ),
    ),
)

_TRAINING: Final = _training_specs()
_CLSTM: Final = _clstm_specs()

PRESETS: Final[Mapping[str, SignalSpec]] = MappingProxyType(
    {s.name: s for s in (*_TRAINING, *_CLSTM, *_MODEL_TEST_SPECS, *_TRAJECTORY_SPECS)}
)
"""Every preset, by name."""

TEST_PRESSURE_SIGNALS: Final = tuple(s.name for s in _MODEL_TEST_SPECS)
"""The four modelling test signals of sec. 5.4.2, in the thesis's order."""
TEST_TRAJECTORIES: Final = tuple(s.name for s in _TRAJECTORY_SPECS)
"""The four control test trajectories of sec. 9.3 / 10.3.2, in the thesis's order."""


def get_preset(name: str) -> SignalSpec:
    """The preset called ``name``.

    Raises:
        SignalError: If there is no such preset; the message lists the valid names.
    """
    try:
        return PRESETS[name]
    except KeyError:
        valid = ", ".join(sorted(PRESETS))
        raise SignalError(f"unknown signal preset {name!r}; valid names: {valid}") from None


def training_set() -> tuple[SignalSpec, ...]:
    """The 8 DRDPI training signals (eqs. 4.1/4.2 x f in 0.2-0.8 Hz), zero baseline first."""
    return _TRAINING


def clstm_training_set() -> tuple[SignalSpec, ...]:
    """The 40 c-LSTM training pressure signals of sec. 10.3.1 (2 forms x 4 f x 5 tau)."""
    return _CLSTM
