"""`follow_trajectory --sim --live`: a Foxglove client sees the run as it happens; `tip_tf`
turns tip/angle into the ROS conventions (joint_states, robot_description, TF).

The client is a plain WebSocket client speaking the protocol Foxglove speaks (the SDK's server
names it ``foxglove.sdk.v1``): it reads the advertised channels, decodes what it receives with
the ROS 2 schema the server advertised (as Foxglove does), and fetches the URDF asset.
"""

from __future__ import annotations

import asyncio
import json
import math
import socket
import struct
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from graph_utils import Children, Probe, node_argv

from catheter_control.tip_tf import URDF_PACKAGE_URL, urdf_text

pytestmark = pytest.mark.slow

SUBPROTOCOL = "foxglove.sdk.v1"
_MESSAGE_DATA = 0x01
_FETCH_ASSET_RESPONSE = 0x04

EXPECTED_TOPICS = {
    "/catheter/pressure/command",
    "/catheter/pressure/measured",
    "/catheter/tip/angle",
    "/catheter/tip/distance",
    "/catheter/angle/desired",
    "/catheter/trajectory",
    "/diagnostics",
    "/catheter/robot_description",
    "/catheter/joint_states",
    "/tf",
    "/tf_static",
}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _decoder(channel: dict[str, Any]) -> Any:
    """Decode with the advertised schema, as Foxglove does (not with our own classes)."""
    from mcap.records import Schema
    from mcap_ros2.decoder import DecoderFactory

    assert channel["encoding"] == "cdr" and channel["schemaEncoding"] == "ros2msg", channel
    schema = Schema(
        id=1, name=channel["schemaName"], encoding="ros2msg", data=channel["schema"].encode()
    )
    decoder = DecoderFactory().decoder_for("cdr", schema)
    assert decoder is not None
    return decoder


async def _watch(url: str, deadline_s: float) -> dict[str, Any]:
    """Connect, subscribe to the bend streams and the model, collect until the stream ends."""
    import websockets

    while True:  # the graph and the server take a while to come up
        try:
            ws = await websockets.connect(url, subprotocols=[SUBPROTOCOL])  # type: ignore[list-item]
            break
        except OSError:
            if time.monotonic() > deadline_s:
                raise
            await asyncio.sleep(0.5)
    out: dict[str, Any] = {"channels": {}, "angles_deg": [], "desired_deg": [], "urdf": None}
    async with ws:
        while not {"/catheter/tip/angle", "/catheter/angle/desired"} <= out["channels"].keys():
            frame = json.loads(await asyncio.wait_for(ws.recv(), deadline_s - time.monotonic()))
            if frame["op"] == "advertise":
                out["channels"].update({c["topic"]: c for c in frame["channels"]})
        angle = out["channels"]["/catheter/tip/angle"]
        desired = out["channels"]["/catheter/angle/desired"]
        decoders = {1: _decoder(angle), 2: _decoder(desired)}
        subs = [{"id": 1, "channelId": angle["id"]}, {"id": 2, "channelId": desired["id"]}]
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
        await ws.send(json.dumps({"op": "fetchAsset", "uri": URDF_PACKAGE_URL, "requestId": 7}))
        # Until the stream ends: follow_trajectory stops the view once the run is scored.
        while time.monotonic() < deadline_s:
            try:
                frame = await asyncio.wait_for(ws.recv(), 1.0)
            except TimeoutError:
                continue
            except websockets.ConnectionClosed:
                break
            if isinstance(frame, str):
                msg = json.loads(frame)
                if msg["op"] == "advertise":
                    out["channels"].update({c["topic"]: c for c in msg["channels"]})
                continue
            if frame[0] == _FETCH_ASSET_RESPONSE:
                _request, status, err_len = struct.unpack_from("<IBI", frame, 1)
                assert status == 0, frame[10 : 10 + err_len]
                out["urdf"] = frame[10 + err_len :].decode()
            elif frame[0] == _MESSAGE_DATA:
                sub_id, _log_time_ns = struct.unpack_from("<IQ", frame, 1)
                msg = decoders[sub_id](frame[13:])
                i = list(msg.name).index("bend")
                key = "angles_deg" if sub_id == 1 else "desired_deg"
                out[key].append(math.degrees(msg.position[i]))
    return out


def test_follow_trajectory_streams_the_run_to_a_foxglove_client(
    children: Children, tmp_path: Path
) -> None:
    path = tmp_path / "up_and_down.csv"
    path.write_text("t_s,angle_deg\n0,0\n2,10\n4,10\n6,0\n")
    port = _free_port()
    proc = children.start(
        "follow_trajectory",
        [
            sys.executable,
            "-m",
            "catheter_control.follow_trajectory",
            "--sim",
            "--file",
            str(path),
            "--live",
            str(port),
            "--out",
            str(tmp_path / "run"),
            "--no-progress",
        ],
    )
    # Start-up (graph, discovery) takes seconds, the run 6 s; a loaded machine is slower.
    seen = asyncio.run(_watch(f"ws://127.0.0.1:{port}", time.monotonic() + 120.0))
    assert proc.wait(60.0) == 0, children.log("follow_trajectory")

    assert seen["channels"].keys() >= EXPECTED_TOPICS, sorted(seen["channels"])
    assert seen["urdf"] == urdf_text()
    # The measured bend seen live tracks the simulated rig: it rose with the set-point to
    # about 10 deg and came back down.
    angles = seen["angles_deg"]
    assert len(angles) > 250, len(angles)  # 250 Hz for several seconds, less what was missed
    assert 8.0 < max(angles) < 12.0, max(angles)
    assert min(angles) < 2.0
    peak = angles.index(max(angles))
    assert angles[-1] < 2.0 and peak < len(angles) - 1, "the tip did not come back down"
    assert max(seen["desired_deg"]) == pytest.approx(10.0, abs=0.01)
    log = children.log("follow_trajectory")
    assert f"live view on ws://localhost:{port}: forwarded" in log, log


def test_tip_tf_publishes_the_model_and_its_transforms(children: Children) -> None:
    """What robot_state_publisher would give, from tip/angle: TF, joint_states, the URDF."""
    pytest.importorskip("tf2_msgs.msg", reason="tf2_msgs is built by scripts/build_interfaces.sh")
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String
    from tf2_msgs.msg import TFMessage

    from catheter_ros import qos
    from catheter_ros.messages import joint_state

    latched = QoSProfile(
        depth=1,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )
    children.start("tip_tf", node_argv("catheter_control.tip_tf"))
    with Probe(children.domain_id) as probe:
        tf = probe.subscribe(TFMessage, "/tf", 100)
        tf_static = probe.subscribe(TFMessage, "/tf_static", latched)
        description = probe.subscribe(String, "robot_description", latched)
        states = probe.subscribe(JointState, "joint_states", 100)
        pub = probe.node.create_publisher(JointState, "tip/angle", qos.STREAM)
        angle_rad = math.radians(20.0)
        stamp_ns = time.time_ns()

        def send_until_seen() -> bool:
            nonlocal stamp_ns
            stamp_ns += 4_000_000
            pub.publish(joint_state(angle_rad, stamp_ns))
            return bool(tf and states and tf_static and description)

        assert probe.spin_until(send_until_seen, 60.0), children.log("tip_tf")
    assert description[-1].msg.data == urdf_text()
    moving = tf[-1].msg.transforms[0]
    assert (moving.header.frame_id, moving.child_frame_id) == ("base_link", "bend_distal")
    yaw = 2.0 * math.atan2(moving.transform.rotation.z, moving.transform.rotation.w)
    assert yaw == pytest.approx(angle_rad)
    fixed = tf_static[-1].msg.transforms[0]
    assert (fixed.header.frame_id, fixed.child_frame_id) == ("bend_distal", "tip")
    assert list(states[-1].msg.name) == ["bend"]
    assert states[-1].msg.position[0] == pytest.approx(angle_rad)
