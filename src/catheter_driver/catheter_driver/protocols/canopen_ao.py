"""Valve set-point through a CANopen analog-output module (CiA 401 style, object 0x6411).

The module's first receive PDO carries the raw output value of channel 1 as an int16,
little-endian; its first transmit PDO reports the raw value it is driving. Default COB-IDs
are the CiA 301 predefined connection set: RPDO1 = 0x200 + node id, TPDO1 = 0x180 + node id.
A module only acts on PDOs in the Operational state, entered by NMT "start remote node"
(COB-ID 0x000, data ``01 <node id>``).

Default scaling: a 0-10 V module (raw 0..32767 = 0..10 V) driving a valve whose 0-10 V input
spans 0..6 bar gauge, so raw 32767 = 6e5 Pa. Set ``full_scale_pa`` to the valve's range (the
thesis's Festo regulator spans 0-3 bar: ``full_scale_pa=3e5``).

This is standard CANopen (CiA 301 NMT and PDOs; the output is the CiA 401 object 0x6411),
which off-the-shelf analog-output modules speak as delivered: nothing needs flashing. The
module must be configured (over SDO or with its vendor's tool), though, because CiA 401's
default mapping differs from the one used here: docs/protocols/canopen_valve.md says what
to set.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

from catheter_driver.protocols import FrameError
from catheter_models.errors import ParameterError

RPDO1_BASE: Final = 0x200
TPDO1_BASE: Final = 0x180
NMT_COB_ID: Final = 0x000
NMT_START_REMOTE_NODE: Final = 0x01
INT16_MIN: Final = -32768
INT16_MAX: Final = 32767


def check_node_id(node_id: int) -> int:
    """``node_id`` if it is a valid CANopen node id (1..127), else ParameterError."""
    if not 1 <= node_id <= 127:
        raise ParameterError(f"CANopen node id must be 1..127, got {node_id!r}")
    return node_id


def rpdo1_cob_id(node_id: int) -> int:
    """Default COB-ID of RPDO1 (set-point to the module): 0x200 + node id."""
    return RPDO1_BASE + check_node_id(node_id)


def tpdo1_cob_id(node_id: int) -> int:
    """Default COB-ID of TPDO1 (read-back from the module): 0x180 + node id."""
    return TPDO1_BASE + check_node_id(node_id)


def encode_nmt_start(node_id: int) -> tuple[int, bytes]:
    """NMT "start remote node" for ``node_id`` as ``(cob_id, data)``; 0 starts all nodes."""
    if node_id != 0:
        check_node_id(node_id)
    return NMT_COB_ID, bytes((NMT_START_REMOTE_NODE, node_id))


def encode_ao_raw(raw: int) -> bytes:
    """Raw analog-output value as PDO data: int16 little-endian.

    Raises:
        ParameterError: ``raw`` outside the int16 range.
    """
    if not INT16_MIN <= raw <= INT16_MAX:
        raise ParameterError(f"AO raw value must be {INT16_MIN}..{INT16_MAX} (int16), got {raw!r}")
    return int(raw).to_bytes(2, "little", signed=True)


def decode_ao_raw(data: bytes, channel: int = 0) -> int:
    """Raw value of AO ``channel`` (0-based) from PDO data of int16 little-endian values.

    Raises:
        FrameError: the PDO is too short to hold that channel.
    """
    end = 2 * (channel + 1)
    if channel < 0 or len(data) < end:
        raise FrameError(
            f"AO PDO of {len(data)} bytes holds no channel {channel} (needs {end} bytes)"
        )
    return int.from_bytes(data[end - 2 : end], "little", signed=True)


@dataclass(frozen=True)
class AoScaling:
    """Linear map between gauge pressure and the module's raw value.

    Attributes:
        raw_at_zero: raw value for 0 Pa gauge (0 V on a 0-10 V module).
        raw_at_full: raw value for ``full_scale_pa`` (32767 = 10 V on a 0-10 V module).
        full_scale_pa: valve pressure at full input, gauge [Pa] (6 bar valve by default).
    """

    raw_at_zero: int = 0
    raw_at_full: int = INT16_MAX
    full_scale_pa: float = 6.0e5

    def __post_init__(self) -> None:
        for name, raw in (("raw_at_zero", self.raw_at_zero), ("raw_at_full", self.raw_at_full)):
            if not INT16_MIN <= raw <= INT16_MAX:
                raise ParameterError(
                    f"{name} must be an int16 ({INT16_MIN}..{INT16_MAX}), got {raw!r}"
                )
        if self.raw_at_full == self.raw_at_zero:
            raise ParameterError("raw_at_full equals raw_at_zero; the scaling would be flat")
        if not (math.isfinite(self.full_scale_pa) and self.full_scale_pa > 0.0):
            raise ParameterError(
                f"full_scale_pa must be finite and > 0 Pa, got {self.full_scale_pa!r}"
            )

    def pa_to_raw(self, gauge_pa: float) -> int:
        """Raw value for a set-point, gauge [Pa], rounded to the nearest step.

        Raises:
            ParameterError: not finite or outside 0..full_scale_pa (the module cannot drive it).
        """
        if not (math.isfinite(gauge_pa) and 0.0 <= gauge_pa <= self.full_scale_pa):
            raise ParameterError(
                f"valve set-point {gauge_pa!r} Pa is outside the AO range "
                f"0..{self.full_scale_pa:g} Pa"
            )
        span = self.raw_at_full - self.raw_at_zero
        return self.raw_at_zero + round(gauge_pa / self.full_scale_pa * span)

    def raw_to_pa(self, raw: int) -> float:
        """Gauge pressure [Pa] for a raw value (may lie outside 0..full_scale_pa)."""
        return (raw - self.raw_at_zero) / (self.raw_at_full - self.raw_at_zero) * self.full_scale_pa
