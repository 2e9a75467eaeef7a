"""Hold a LOCALHOST graph's DDS sockets on the loopback interface.

``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (what ``follow_trajectory --sim``, ``commission
--sim`` and the container image set) limits whom a participant discovers, not where it
listens: with Fast DDS's built-in transports every UDP socket is bound to ``0.0.0.0``, so a
host on the network can still send datagrams to a node that commands a catheter. Before a
process creates its first participant, :func:`use_loopback_profile` points Fast DDS at a
profile (``fastdds_loopback.xml``, shipped beside this module) whose only transports are
UDPv4 on 127.0.0.1 and shared memory.

It steps aside where a person chose otherwise: another discovery range, a profile of their
own (``FASTDDS_DEFAULT_PROFILES_FILE`` or the older ``FASTRTPS_DEFAULT_PROFILES_FILE``),
``FASTDDS_BUILTIN_TRANSPORTS``, a middleware other than Fast DDS, or
``CATHETER_DDS_LOOPBACK=0``. Measured with the venv's Kilted wheels (tests/integration/
test_dds_loopback_live.py): the discovery and user ports move to 127.0.0.1; one socket on an
ephemeral port stays on ``0.0.0.0`` and one on the host's address (Fast DDS's own, not
configurable from a profile as far as we found), so a rig keeps its host firewall.
"""

from __future__ import annotations

import os
from collections.abc import MutableMapping
from pathlib import Path

LOOPBACK_PROFILE = Path(__file__).with_name("fastdds_loopback.xml")
"""The Fast DDS profile: UDPv4 on 127.0.0.1 and shared memory, nothing else."""

OPT_OUT_ENV = "CATHETER_DDS_LOOPBACK"
"""Set to ``0`` to keep Fast DDS's built-in transports under LOCALHOST."""

_USER_CHOICES = (
    "FASTDDS_DEFAULT_PROFILES_FILE",
    "FASTRTPS_DEFAULT_PROFILES_FILE",
    "FASTDDS_BUILTIN_TRANSPORTS",
)


def loopback_profile_reason(env: MutableMapping[str, str]) -> str | None:
    """Why the loopback profile does not apply to ``env``, or None when it does."""
    if env.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "").upper() != "LOCALHOST":
        return "discovery is not limited to LOCALHOST"
    if env.get(OPT_OUT_ENV, "1") == "0":
        return f"{OPT_OUT_ENV}=0"
    chosen = [key for key in _USER_CHOICES if env.get(key)]
    if chosen:
        return f"{chosen[0]} is set"
    rmw = env.get("RMW_IMPLEMENTATION", "")
    if rmw and not rmw.startswith("rmw_fastrtps"):
        return f"RMW_IMPLEMENTATION={rmw} is not Fast DDS"
    if not LOOPBACK_PROFILE.is_file():
        return f"{LOOPBACK_PROFILE} is missing from the installation"
    return None


def use_loopback_profile(env: MutableMapping[str, str] | None = None) -> bool:
    """Point Fast DDS at the loopback profile in ``env`` (this process's) if it applies.

    Call it before the first participant of the process exists (``rclpy.init`` and the first
    node); processes started from ``env`` afterwards inherit it. Returns whether it was set.
    """
    target = os.environ if env is None else env
    if loopback_profile_reason(target) is not None:
        return False
    target["FASTDDS_DEFAULT_PROFILES_FILE"] = str(LOOPBACK_PROFILE)
    return True
