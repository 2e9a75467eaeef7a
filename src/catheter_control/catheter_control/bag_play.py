"""``bag_play``: publish a recorded bag over DDS with its recorded timing and offered QoS.

A session recorded once can be replayed into a running recorder, into the compensator (its
``trajectory``), into Foxglove, or into anything that learns from topics::

    ros2 run catheter_control bag_play bags/training --rate 2 --topics pressure/command tip/angle
    bag_play runs/x/bag --start-offset-s 10 --loop --remap /catheter/tip/angle:=/replay/angle

Messages go out as recorded (the serialized bytes, header stamps untouched), spaced by their
recorded log times divided by ``--rate``. Each topic is published with the QoS its publisher
offered when it was recorded (streams reliable, ``trajectory`` transient local), so a reliable
recorder matches and gets every message. ``--wait-for-subscribers-s`` holds the start until
every topic has a subscriber (discovery takes seconds, and a recorder that has not matched yet
would miss the start). Ctrl-C stops cleanly after the message in flight and says how far it got.

A bag holds ``pressure/command`` and ``trajectory``; played under those names on the rig's
ROS domain, the valve driver or the compensator would act on them. So they are refused unless
remapped, left out with ``--topics``, or allowed with ``--allow-commands`` (on an isolated
domain). The drivers' own limits and watchdog still hold for whatever arrives.

Exit codes: 0 played to the end (or stopped by Ctrl-C), 2 refused (unreadable bag, no such
topic, commands not remapped, bad option).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from tqdm import tqdm

from catheter_models.bag.playback import Player
from catheter_models.contract import PRESSURE_COMMAND, TRAJECTORY
from catheter_models.errors import CatheterError, ParameterError

EXIT_REFUSED = 2


def _parse(argv: Sequence[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog="bag_play", description="Publish a recorded bag over DDS with its timing and QoS."
    )
    p.add_argument("bag", type=Path, help="bag directory or .mcap file")
    p.add_argument("--rate", type=float, default=1.0, help="playback speed factor (2: twice)")
    p.add_argument(
        "--start-offset-s", type=float, default=0.0, help="skip this much of the bag's start [s]"
    )
    p.add_argument("--loop", action="store_true", help="play again from the start until Ctrl-C")
    p.add_argument(
        "--topics",
        nargs="+",
        default=None,
        metavar="TOPIC",
        help="only these (full names, or names relative to the bag's namespace)",
    )
    p.add_argument(
        "--remap",
        action="append",
        default=[],
        metavar="FROM:=TO",
        help="publish the recorded topic FROM on TO (full names)",
    )
    p.add_argument(
        "--wait-for-subscribers-s",
        type=float,
        default=0.0,
        help="wait up to this long until every topic has a subscriber before starting [s]",
    )
    p.add_argument(
        "--allow-commands",
        action="store_true",
        help="publish pressure/command and trajectory under their own names (a valve driver "
        "on this domain would execute them); without it they must be remapped or left out",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = p.parse_args(argv)
    if not (args.rate > 0.0 and args.rate < float("inf")):
        raise ParameterError(f"--rate must be a positive factor, got {args.rate}")
    if not args.start_offset_s >= 0.0:
        raise ParameterError(f"--start-offset-s must be >= 0, got {args.start_offset_s}")
    if not args.wait_for_subscribers_s >= 0.0:
        raise ParameterError(
            f"--wait-for-subscribers-s must be >= 0, got {args.wait_for_subscribers_s}"
        )
    return args


def _remaps(pairs: Sequence[str]) -> dict[str, str]:
    out = {}
    for pair in pairs:
        src, sep, dst = pair.partition(":=")
        if not sep or not src.startswith("/") or not dst.startswith("/"):
            raise ParameterError(f"--remap {pair!r}: expected /from/topic:=/to/topic")
        out[src] = dst
    return out


def moves_the_catheter(topic: str) -> bool:
    """Whether a valve driver or the compensator acts on ``topic`` (full name)."""
    return any(topic.endswith("/" + spec.name) for spec in (PRESSURE_COMMAND, TRAJECTORY))


def _profile(qos: dict[str, Any]) -> Any:
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=qos["depth"],
        reliability=ReliabilityPolicy.RELIABLE
        if qos["reliability"] == "reliable"
        else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL
        if qos["durability"] == "transient_local"
        else DurabilityPolicy.VOLATILE,
    )


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from catheter_ros.dds_profile import use_loopback_profile
    from catheter_ros.messages import message_class
    from catheter_ros.node_main import install_stop_handlers

    argv = sys.argv if argv is None else ["bag_play", *argv]
    try:
        # Ours are what comes before --ros-args (rcl would take a bare FROM:=TO as its own).
        ours = argv[1 : argv.index("--ros-args")] if "--ros-args" in argv else argv[1:]
        args = _parse(ours)
        player = Player(args.bag, args.topics, _remaps(args.remap))
        moving = [
            t.out for t in player.topics.values() if t.out == t.name and moves_the_catheter(t.name)
        ]
        if moving and not args.allow_commands:
            raise ParameterError(
                f"refused: the bag holds {', '.join(moving)}; played under the recorded name, "
                "a valve driver on this ROS domain would move the catheter. Remap it away (--remap "
                f"{moving[0]}:=/replay{moving[0]}), leave it out (--topics ...), or pass "
                "--allow-commands on an isolated ROS_DOMAIN_ID"
            )
    except (CatheterError, OSError) as exc:
        print(f"bag_play: {exc}", file=sys.stderr)
        return EXIT_REFUSED
    stop = install_stop_handlers()
    use_loopback_profile()
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    try:
        node = rclpy.create_node("bag_play")
        pubs: dict[str, Any] = {
            t.name: node.create_publisher(message_class(t.msgtype), t.out, _profile(t.qos))
            for t in player.topics.values()
        }
        for t in player.topics.values():
            node.get_logger().info(
                f"{t.name} -> {t.out} ({t.msgtype}, {t.qos['reliability']}, "
                f"{t.qos['durability']}, depth {t.qos['depth']})"
            )
        if args.wait_for_subscribers_s > 0.0:
            until = time.monotonic() + args.wait_for_subscribers_s
            while time.monotonic() < until and not stop.is_set():
                if all(p.get_subscription_count() > 0 for p in pubs.values()):
                    break
                stop.wait(0.05)
            lonely = [n for n, p in pubs.items() if p.get_subscription_count() == 0]
            if lonely:
                node.get_logger().warning(f"starting with no subscriber on {', '.join(lonely)}")
        span_s = max(0.0, player.duration_s - args.start_offset_s)
        played = 0
        rounds = 0
        while not stop.is_set():
            rounds += 1
            bar = tqdm(
                total=round(span_s, 1),
                unit="s",
                desc=f"bag_play x{args.rate:g}" + (f" (round {rounds})" if args.loop else ""),
                disable=args.no_progress,
                bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} s bag time",
            )
            t0_s = time.monotonic()
            base_ns: int | None = None
            shown_s = 0.0
            for topic, log_ns, raw in player.messages(args.start_offset_s):
                base_ns = log_ns if base_ns is None else base_ns
                bag_s = (log_ns - base_ns) * 1e-9
                wait_s = t0_s + bag_s / args.rate - time.monotonic()
                if wait_s > 0.0 and stop.wait(wait_s):
                    break
                pubs[topic].publish(raw)
                played += 1
                target_s = min(round(bag_s, 1), bar.total)
                if target_s > shown_s:
                    bar.update(round(target_s - shown_s, 1))
                    shown_s = target_s
            bar.close()
            if not args.loop:
                break
        how = "stopped" if stop.is_set() else "played"
        print(
            f"bag_play: {how}: {played} messages on {len(pubs)} topics from {player.layout.path}"
            + (f" ({rounds} rounds)" if args.loop else ""),
            file=sys.stderr,
        )
        # Reliable publishers keep what a subscriber has not acknowledged yet: give it a
        # moment to ask, rather than destroy the history under it.
        time.sleep(0.5)
        node.destroy_node()
    finally:
        rclpy.try_shutdown()
    return 0


def entry() -> None:
    """Console-script wrapper."""
    sys.exit(main())


if __name__ == "__main__":
    entry()
