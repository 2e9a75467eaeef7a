"""Over DDS: under LOCALHOST discovery, a node's DDS sockets listen on the loopback interface.

``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` alone leaves every Fast DDS socket bound to
``0.0.0.0``; every catheter node loads ``catheter_ros/fastdds_loopback.xml`` then
(:mod:`catheter_ros.dds_profile`). A simulated rig started as a process is checked from
/proc: its participant's ports (those of its domain) are on 127.0.0.1, it still talks to a
participant without the profile (the test's probe), and with ``CATHETER_DDS_LOOPBACK=0`` the
same ports are on ``0.0.0.0`` again (the check can tell the two apart).
"""

from __future__ import annotations

import socket
import struct
import time
from pathlib import Path

import pytest
from fault_log import FaultRecord
from graph_utils import Children, Probe, node_argv
from sensor_msgs.msg import FluidPressure

from catheter_models.contract import PRESSURE_MEASURED
from catheter_ros import qos

pytestmark = [pytest.mark.slow]

DOMAIN_PORTS = 250
"""Fast DDS's port mapping: each domain owns 250 ports from 7400 + 250 x domain."""


def _family(pid: int) -> list[int]:
    """``pid`` and its descendants (the ROS wheels' bootstrap may run the node as a child)."""
    parents: dict[int, int] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue  # exited meanwhile
        parents[int(stat.parent.name)] = int(fields[1])
    family = [pid]
    for member in family:
        family.extend(child for child, parent in parents.items() if parent == member)
    return family


def _udp_ports(pid: int) -> dict[int, str]:
    """The UDP ports process ``pid`` (and its children) listen on, with each one's address."""
    inodes = set()
    for member in _family(pid):
        try:
            fds = list(Path(f"/proc/{member}/fd").iterdir())
        except OSError:
            continue
        for fd in fds:
            try:
                target = str(fd.readlink())
            except OSError:
                continue  # closed meanwhile
            if target.startswith("socket:["):
                inodes.add(target[8:-1])
    bound: dict[int, str] = {}
    for line in Path("/proc/net/udp").read_text().splitlines()[1:]:
        fields = line.split()
        if fields[9] in inodes:
            address_hex, port_hex = fields[1].split(":")
            address = socket.inet_ntoa(struct.pack("<I", int(address_hex, 16)))
            bound[int(port_hex, 16)] = address
    return bound


def _domain_ports(children: Children, pid: int) -> dict[int, str]:
    """The ports of ``pid`` in its ROS domain's range, once it has opened them."""
    low = 7400 + DOMAIN_PORTS * children.domain_id
    end = time.monotonic() + 30.0
    while time.monotonic() < end:
        ports = {p: a for p, a in _udp_ports(pid).items() if low <= p < low + DOMAIN_PORTS}
        if len(ports) >= 2:  # metatraffic and user unicast
            return ports
        time.sleep(0.2)
    raise AssertionError(f"no DDS ports of domain {children.domain_id} opened by pid {pid}")


def _sim(children: Children, name: str) -> int:
    proc = children.start(name, node_argv("catheter_driver.sim_hardware_node"))
    return proc.pid


@pytest.mark.fault(
    "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST: are a node's DDS ports open to the network?",
    safe="the node's discovery and user ports listen on 127.0.0.1 only (Fast DDS profile)",
    category="input",
)
def test_a_node_under_localhost_discovery_listens_on_loopback_only(
    children: Children, fault: FaultRecord
) -> None:
    pid = _sim(children, "sim_hardware")
    ports = _domain_ports(children, pid)
    fault.check(
        "the domain's ports bound to 127.0.0.1 only",
        set(ports.values()) == {"127.0.0.1"},
        str(ports),
    )
    fault.safe_after(0.0)
    # And it is still reachable over DDS from a participant with the built-in transports.
    with Probe(children.domain_id) as probe:
        measured = probe.subscribe(FluidPressure, PRESSURE_MEASURED.name, qos.RECORD)
        fault.check(
            "still heard over DDS by a participant without the profile",
            probe.spin_until(lambda: len(measured) > 50, 30.0),
            children.all_logs(),
        )


def test_opting_out_keeps_fast_dds_builtin_sockets_on_every_interface(
    children: Children,
) -> None:
    children.env["CATHETER_DDS_LOOPBACK"] = "0"
    pid = _sim(children, "sim_hardware_builtin")
    ports = _domain_ports(children, pid)
    assert "0.0.0.0" in ports.values(), ports
