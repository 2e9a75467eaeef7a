"""Hysteresis operators (play, deadband, GPI envelope) and the operator chains built from them.

See :mod:`catheter_models.hysteresis.operators` for which thesis equation each kernel
implements: that module holds the operators and the forward chain, ``inverse`` the analytic
inverses, ``gpi_kernels`` the GPI, ``population`` the identification's loss. The models
(``models.drdpi``, ``models.gpi``, ``models.idrdpi``) and their streams all run these
kernels; there is no second copy.
"""

from catheter_models.hysteresis.gpi_kernels import (
    gpi_coefficients,
    gpi_inverse_run,
    gpi_run,
    invert_gpi,
)
from catheter_models.hysteresis.inverse import invert_chain, invert_deadband, invert_pi
from catheter_models.hysteresis.operators import (
    chain_run,
    chain_state_size,
    deadband,
    deadband_sum,
    drdpi_coefficients,
    envelope,
    envelope_inverse,
    pack_chain,
    play,
    unpack_chain,
)

__all__ = [
    "chain_run",
    "chain_state_size",
    "deadband",
    "deadband_sum",
    "drdpi_coefficients",
    "envelope",
    "envelope_inverse",
    "gpi_coefficients",
    "gpi_inverse_run",
    "gpi_run",
    "invert_chain",
    "invert_deadband",
    "invert_gpi",
    "invert_pi",
    "pack_chain",
    "play",
    "unpack_chain",
]
