"""When the loopback Fast DDS profile applies, and when a person's own choice wins."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest

from catheter_ros.dds_profile import (
    LOOPBACK_PROFILE,
    loopback_profile_reason,
    use_loopback_profile,
)

LOCAL = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}


def test_localhost_discovery_gets_the_loopback_profile() -> None:
    env = dict(LOCAL)
    assert use_loopback_profile(env)
    assert env["FASTDDS_DEFAULT_PROFILES_FILE"] == str(LOOPBACK_PROFILE)


@pytest.mark.parametrize(
    ("extra", "said"),
    [
        ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}, "not limited to LOCALHOST"),
        ({"CATHETER_DDS_LOOPBACK": "0"}, "CATHETER_DDS_LOOPBACK=0"),
        ({"FASTDDS_DEFAULT_PROFILES_FILE": "/etc/rig.xml"}, "FASTDDS_DEFAULT_PROFILES_FILE"),
        ({"FASTRTPS_DEFAULT_PROFILES_FILE": "/etc/rig.xml"}, "FASTRTPS_DEFAULT_PROFILES_FILE"),
        ({"FASTDDS_BUILTIN_TRANSPORTS": "UDPv4"}, "FASTDDS_BUILTIN_TRANSPORTS"),
        ({"RMW_IMPLEMENTATION": "rmw_cyclonedds_cpp"}, "not Fast DDS"),
    ],
)
def test_a_choice_of_ones_own_is_left_alone(extra: dict[str, str], said: str) -> None:
    env = {**LOCAL, **extra}
    before = dict(env)
    assert said in (loopback_profile_reason(env) or "")
    assert not use_loopback_profile(env)
    assert env == before


def test_the_shipped_profile_allows_loopback_and_shared_memory_only() -> None:
    ns = {"d": "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"}
    root = ET.parse(LOOPBACK_PROFILE).getroot()
    kinds = {
        t.findtext("d:type", namespaces=ns) for t in root.iterfind(".//d:transport_descriptor", ns)
    }
    assert kinds == {"UDPv4", "SHM"}
    assert [a.text for a in root.iterfind(".//d:interfaceWhiteList/d:address", ns)] == ["127.0.0.1"]
    assert root.findtext(".//d:useBuiltinTransports", namespaces=ns) == "false"
