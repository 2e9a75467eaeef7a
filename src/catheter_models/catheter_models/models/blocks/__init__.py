"""Physical-effect blocks: the identifiable approximations of the effect catalogue (docs/lab.md).

A grey-box model is a chain: input blocks (pressure to pressure), the thesis's DRDPI
(play, rate dependence, deadband, asymmetry and saturation: the default chain), then output
blocks (bend to bend). Each block here is the *approximation* a person would write down to
identify an effect, not the plant's physics: the simulated plant fills the muscle through an
orifice (a nonlinear flow), the block is a first-order lag; the plant creeps through two
Maxwell branches in the bending stiffness, inside the force balance with the wire's friction,
the block delays a share of the bend itself through two lags. So a diagnosis that finds the
plant's effect with the block is a test of the method, not of code agreeing with itself.

Blocks work on one recording at a time, from rest, in the chain's internal units: input
blocks on pressure in bar, output blocks on bend in degrees; their parameters are SI.

An effect is one :class:`~.base.Block` subclass in one module of this package, which says
everything about itself: its form and bounds, the residual test it leaves, the regimes where
it shows, its rival on the core's other side and its counterpart in the simulated plant.
:func:`register` puts it in the catalogue (:data:`BLOCKS`), which the lab's diagnosis,
``catheter-lab effects`` and ``catheter-lab add`` all read; a form outside the catalogue
(:data:`CHECKS`) is fitted only as a rival.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from typing import Final, TypeVar

from catheter_models.errors import ParameterError
from catheter_models.models.blocks.base import (
    DEFAULT_CHAIN_EFFECTS,
    MOST_TIP_DAMPING,
    PLAIN_LAG_RATE_BAR_PER_S,
    SHORTEST_TUBE_S,
    Block,
    BlockParam,
    Side,
    Step,
)

B = TypeVar("B", bound=type[Block])

BLOCKS: Final[dict[str, type[Block]]] = {}
"""The catalogue: blocks by effect name, in chain order within each side. A diagnosis tries
and names these."""

CHECKS: Final[dict[str, type[Block]]] = {}
"""Forms outside the catalogue: a diagnosis fits them only as a block's :attr:`Block.rival`,
and never names them."""


def register(cls: B, *, catalogue: bool = True) -> B:
    """Add an effect's block to the catalogue (or, ``catalogue=False``, to the checks).

    Its place in the chain is after the blocks registered before it on its side. A name
    already taken, by a block or by the default chain, is refused.
    """
    name = cls.effect
    if name in BLOCKS or name in CHECKS or name in DEFAULT_CHAIN_EFFECTS:
        raise ParameterError(f"an effect named {name!r} is registered already")
    if catalogue and not (cls.evidence_test and cls.regimes):
        raise ParameterError(
            f"block {name!r} names no evidence_test or regimes: a catalogue effect must say "
            "where it shows, or the diagnosis cannot judge it"
        )
    (BLOCKS if catalogue else CHECKS)[name] = cls
    return cls


def unregister(effect: str) -> None:
    """Take an effect out again (a test's toy effect, say)."""
    BLOCKS.pop(effect, None)
    CHECKS.pop(effect, None)


class _Forms(Mapping[str, type[Block]]):
    """Every block a grey-box chain can hold: the catalogue, then the checks (live)."""

    def __getitem__(self, effect: str) -> type[Block]:
        return BLOCKS[effect] if effect in BLOCKS else CHECKS[effect]

    def __iter__(self) -> Iterator[str]:
        yield from BLOCKS
        yield from CHECKS

    def __len__(self) -> int:
        return len(BLOCKS) + len(CHECKS)


FORMS: Final[Mapping[str, type[Block]]] = _Forms()
"""Every block a grey-box chain can hold, in chain order within each side."""


def block(effect: str) -> Block:
    """The block of ``effect``; ParameterError names the known ones."""
    if effect in DEFAULT_CHAIN_EFFECTS:
        raise ParameterError(
            f"{effect!r} is part of the default chain (the DRDPI) already; blocks that can be "
            f"added: {', '.join(FORMS)}"
        )
    cls = FORMS.get(effect)
    if cls is None:
        raise ParameterError(
            f"unknown effect {effect!r}; blocks that can be added: {', '.join(FORMS)} "
            f"(the DRDPI carries {', '.join(DEFAULT_CHAIN_EFFECTS)})"
        )
    return cls()


def ordered(effects: Sequence[str]) -> tuple[str, ...]:
    """Effects in chain order (input blocks, then output blocks, catalogue order); checked."""
    for e in effects:
        block(e)
    if len(set(effects)) != len(effects):
        raise ParameterError(f"an effect is listed twice: {list(effects)}")
    return tuple(e for e in FORMS if e in effects)


# The built-in effects, in chain order within each side.
from catheter_models.models.blocks.checks import OutputLag, SlowFill  # noqa: E402
from catheter_models.models.blocks.creep import Creep  # noqa: E402
from catheter_models.models.blocks.drift import Drift  # noqa: E402
from catheter_models.models.blocks.pneumatic_lag import PneumaticLag  # noqa: E402
from catheter_models.models.blocks.tip_dynamics import TipDynamics  # noqa: E402
from catheter_models.models.blocks.transport_delay import TransportDelay  # noqa: E402

for _catalogued in (TransportDelay, PneumaticLag, Creep, TipDynamics, Drift):
    register(_catalogued)
for _check in (SlowFill, OutputLag):
    register(_check, catalogue=False)

__all__ = [
    "BLOCKS",
    "CHECKS",
    "DEFAULT_CHAIN_EFFECTS",
    "FORMS",
    "MOST_TIP_DAMPING",
    "PLAIN_LAG_RATE_BAR_PER_S",
    "SHORTEST_TUBE_S",
    "Block",
    "BlockParam",
    "Creep",
    "Drift",
    "OutputLag",
    "PneumaticLag",
    "Side",
    "SlowFill",
    "Step",
    "TipDynamics",
    "TransportDelay",
    "block",
    "ordered",
    "register",
    "unregister",
]
