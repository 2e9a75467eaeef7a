"""Hysteresis cores: the law at the middle of a grey-box chain, which the lab can change.

The thesis's DRDPI fixes play, rate dependence, deadband, asymmetry and saturation in one
parametric shape (exponentially decaying play weights on evenly spaced thresholds, a knee
of deadband operators after them). A real catheter's loops need not have that shape, and a
core of the wrong shape absorbs add-on effects (its rate-dependent thresholds make it late as
a lag does) and leaves an error as large as the effect to be found. So the core is a choice:

``drdpi``
    The thesis's DRDPI (ch. 5), identified by its global search: 12 parameters.
``free_pi``
    A Prandtl-Ishlinskii operator with free weights on a grid of play thresholds, applied to
    the pressure shifted by a grid of opening pressures, ``y = c + sum_ij w_ij
    Φ_{r_i g(p) + β|ṡ_j|}[max(p - d_j, 0)]``: the knee, the loop's width and shape at each
    pressure, saturation (negative weights at high d_j) and asymmetry are all learnt, by
    linear least squares for each rate factor β and tension share γ. The thresholds scale
    with the pressure above an onset ``p_0``, ``g(p) = 1 - γ + γ (p - p_0)⁺ / (p_ref - p_0)``:
    the wire's friction in the sheath grows with its tension (the capstan effect), and the
    muscle pulls only above its opening pressure, so a vented muscle lets the tip come home
    while a pulled one holds it. With γ = 0 every loop is as wide at rest as under load,
    and the model keeps a residual bend after vents that depends on the last excursion
    (on two foreign plants that was most of the held-out error with nothing hidden). The
    loop shape is otherwise free; the laws it can form are those with the wiping-out
    property (Preisach-like).
``viscous_pi``
    ``free_pi``'s plays and tension-grown thresholds with no rate in any threshold, and one
    explicit viscous lag of the bend of at most 20 ms (a damper beside the bending section's
    stiffness). Rate-independent by construction but for that term, so it cannot take up a
    tube's lag, a dead time, creep, drift or a ringing tip before a block is tried.
``boucwen``
    A Bouc-Wen differential hysteresis on a smooth-knee pressure, ``dz = ṡ - b|ṡ||z|^(n-1)z -
    g ṡ|z|^n``, ``y = c0 + c1 s + c2 z + c3 s²``: smooth loops whose width saturates, with a
    hysteretic state that a play grid only approximates.

Cores work in the chain's internal units (pressure in bar in, bend in degrees out). A core
whose output is linear in its weights (``free_pi``) is refitted exactly inside every block
search (variable projection): with a block's time constant on a grid, the core is solved
again at each point, so an effect the core could mimic is still found where it belongs.

Each core is a module of this package beside the operators it runs (``drdpi``, ``gpi``,
``free_pi``, ``viscous_pi``, ``boucwen``), on the contract in :mod:`.base`. A new law is a
:class:`Core` in a module of its own, listed in :data:`CORES`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Final

from catheter_models.errors import ParameterError
from catheter_models.models.cores.base import (
    RATE_FILTER_S,
    TENSION_REF_BAR,
    TENSION_SCALE_MAX,
    Core,
    one_blas_thread,
)
from catheter_models.models.cores.boucwen import BoucWen
from catheter_models.models.cores.drdpi import DRDPICore
from catheter_models.models.cores.free_pi import FreePI
from catheter_models.models.cores.gpi import GPICore
from catheter_models.models.cores.viscous_pi import MOST_VISCOUS_S, ViscousPI

CORES: Final[Mapping[str, type[Core]]] = {
    c.name: c for c in (DRDPICore, FreePI, BoucWen, GPICore, ViscousPI)
}
"""Cores by name; the first is the thesis's default."""


def make_core(name: str, settings: Mapping[str, Any] | None = None) -> Core:
    """A core by name with its settings; ParameterError names the known cores."""
    cls = CORES.get(name)
    if cls is None:
        raise ParameterError(f"unknown core {name!r}; known cores: {', '.join(CORES)}")
    try:
        return cls(**dict(settings or {}))
    except TypeError as exc:
        raise ParameterError(f"core {name!r}: {exc}") from None


__all__ = [
    "CORES",
    "MOST_VISCOUS_S",
    "RATE_FILTER_S",
    "TENSION_REF_BAR",
    "TENSION_SCALE_MAX",
    "BoucWen",
    "Core",
    "DRDPICore",
    "FreePI",
    "GPICore",
    "ViscousPI",
    "make_core",
    "one_blas_thread",
]
