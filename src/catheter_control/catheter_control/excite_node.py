"""``excite``: open-loop excitation, data acquisition as in thesis ch. 4.

Publishes one of the thesis's pressure signals on ``pressure/command`` at ``rate_hz`` (from its
own deadline loop, stamped with the intended application time), then holds zero pressure for
``tail_s`` so the recording ends at rest, and exits. The whole signal is checked against the
pressure range before the first sample goes out.
"""

from __future__ import annotations

import threading
import time

import numpy as np
import rclpy
from sensor_msgs.msg import FluidPressure

from catheter_models.contract import (
    CONTROL_RATE_HZ,
    MAX_PRESSURE_PA,
    PRESSURE_COMMAND,
    PRESSURE_LIMIT_HARD_PA,
)
from catheter_models.errors import SignalError
from catheter_models.lab.signals import lab_spec
from catheter_models.limits import BoundedParam
from catheter_models.signals import (
    check_pressure_signal,
    clstm_training_set,
    get_preset,
    training_set,
)
from catheter_models.units import AMBIENT_PRESSURE_PA
from catheter_ros import diagnostics, messages, qos
from catheter_ros.loop_node import LoopNode
from catheter_ros.node_main import run_node
from catheter_ros.params import declare_float, declare_int, declare_plain

_RATE = BoundedParam("rate_hz", CONTROL_RATE_HZ, 10.0, 2000.0, "command rate [Hz]")
_PMAX = BoundedParam(
    "max_pressure_pa",
    MAX_PRESSURE_PA,
    0.0,
    PRESSURE_LIMIT_HARD_PA,
    "refuse signals above this, gauge [Pa]",
)
_TAIL = BoundedParam("tail_s", 1.0, 0.0, 60.0, "zero pressure held after the signal [s]")
_LEAD_IN = BoundedParam("lead_in_s", 0.5, 0.0, 60.0, "zero pressure sent before the signal [s]")
_WAIT = BoundedParam("wait_for_subscriber_s", 10.0, 0.0, 600.0, "wait this long for a listener [s]")
_SLEW = BoundedParam(
    "ramp_down_pa_per_s", 2.0e5, 1.0e3, 1.0e7, "slew of the ramp to zero after a signal [Pa/s]"
)
_LINGER_S = 0.5
_AMB = BoundedParam(
    "ambient_pressure_pa", AMBIENT_PRESSURE_PA, 5.0e4, 1.2e5, "ambient pressure [Pa]"
)


class ExciteNode(LoopNode):
    """Publishes a whole pressure signal, then signals ``done``."""

    def __init__(self) -> None:
        super().__init__("excite")
        name = str(
            declare_plain(
                self,
                "signal",
                "training",
                "thesis pressure preset, a comma-separated list of them, or a protocol: "
                "'training' (the 8 signals of thesis 4.1.1) or 'clstm_training' (sec. 10.3.1)",
            )
        )
        self.rate_hz = declare_float(self, "rate_hz", _RATE)
        max_pa = declare_float(self, "max_pressure_pa", _PMAX)
        tail_s = declare_float(self, "tail_s", _TAIL)
        ramp_pa_per_s = declare_float(self, "ramp_down_pa_per_s", _SLEW)
        self.wait_s = declare_float(self, "wait_for_subscriber_s", _WAIT)
        # Discovery is pairwise: one matched subscriber says nothing about the others. A
        # recording needs the rig *and* the recorder, so wait for as many as are expected.
        self.min_subscribers = declare_int(
            self,
            "min_subscribers",
            1,
            low=1,
            high=100,
            doc="start once this many subscribe to the command topic (rig + recorder = 2)",
        )
        lead_in_s = declare_float(self, "lead_in_s", _LEAD_IN)
        self.ambient_pa = declare_float(self, "ambient_pressure_pa", _AMB)
        if name == "training":
            specs = training_set()
        elif name == "clstm_training":
            specs = clstm_training_set()
        else:
            # The lab's plateau and steps excitations (lab_steps_<seed>: what
            # `catheter-lab tune` identifies the loop from) are named by seed, not listed.
            specs = tuple(lab_spec(n.strip()) or get_preset(n.strip()) for n in name.split(","))
        # Zero pressure first: a listener that matched a moment late misses rest, not signal.
        pieces = [np.zeros(round(lead_in_s * self.rate_hz))]
        tail = np.zeros(round(tail_s * self.rate_hz))
        for spec in specs:
            if spec.kind != "pressure":
                raise SignalError(
                    f"preset {spec.name!r} is an angle trajectory; excite sends pressure"
                )
            signal = spec.generate(self.rate_hz)
            check_pressure_signal(signal.values_si, 0.0, max_pa)
            # Each signal ends at rest, so the next one starts from the same state as the
            # thesis's separate recordings did. Signals with a baseline (eq. 4.2) end at
            # 1.5 bar: ramp down instead of stepping the valve.
            last_pa = float(signal.values_si[-1])
            n_ramp = int(np.ceil(last_pa / ramp_pa_per_s * self.rate_hz))
            ramp = np.linspace(last_pa, 0.0, n_ramp + 1)[1:] if n_ramp > 0 else np.zeros(0)
            pieces += [signal.values_si, ramp, tail]
        self.values_pa = np.concatenate(pieces)
        self.ramp_pa_per_s = ramp_pa_per_s
        self._sent_i = -1
        """Index of the newest sample published (loop thread); -1 before the first."""
        self.published = 0
        """Samples published: fewer than the signal's when the loop missed deadlines (a
        skipped tick's sample is never sent; its stamp is a gap in the recording)."""
        self.spec_names = [spec.name for spec in specs]
        self.signal_name = name
        self.done = threading.Event()
        # The command stream: QoS overridable by parameter (REP 2003), as the compensator's.
        self._pub = qos.overridable_publisher(
            self, FluidPressure, PRESSURE_COMMAND.name, qos.STREAM
        )
        self._pub_diag = diagnostics.create_diagnostics_publisher(self)
        self._first_k: int | None = None
        self._wait_until_s = 0.0
        self.failure = ""
        self.create_loop(self.rate_hz, self._tick)
        self.get_logger().info(
            f"signal {name!r} ({len(specs)} part(s)): {self.values_pa.size / self.rate_hz:.1f} s "
            f"at {self.rate_hz:g} Hz, peak {self.values_pa.max() / 1e5:.2f} bar"
        )

    def start(self) -> None:
        """Start the loop; sending begins once something listens on the command topic."""
        self._wait_until_s = time.monotonic() + self.wait_s
        super().start()

    def _tick(self, k: int, deadline_s: float) -> None:
        if self._first_k is None:
            # Commands into the void are not data acquisition: wait for the rig to listen.
            if self._pub.get_subscription_count() >= self.min_subscribers:
                self._first_k = k
            elif deadline_s > self._wait_until_s:
                self.failure = (
                    f"{self._pub.get_subscription_count()} of {self.min_subscribers} expected "
                    f"subscribers on {self.resolve_topic_name(PRESSURE_COMMAND.name)} after "
                    f"{self.wait_s:g} s; is the rig (or sim_hardware) running?"
                )
                self.done.set()
            return
        i = k - self._first_k
        if i >= self.values_pa.size:
            self.done.set()
            return
        stamp_ns = self.stamp_ns(deadline_s)
        self._pub.publish(
            messages.fluid_pressure(float(self.values_pa[i]), stamp_ns, "", self.ambient_pa)
        )
        self._sent_i = i
        self.published += 1

    def close(self) -> None:
        """Stop sending (idempotent); stopped mid-signal, ramp to zero first.

        A stop request (SIGINT, SIGTERM: a person, or ``commission`` when its recording
        failed) mid-signal ends with the pressure ramped down at ``ramp_down_pa_per_s``, as
        the signals' own ends are, not with the valve held until the driver's watchdog vents.
        """
        i = self._sent_i
        if self._first_k is not None and not self.done.is_set() and i >= 0:
            last_pa = float(self.values_pa[i])
            n_ramp = int(np.ceil(last_pa / self.ramp_pa_per_s * self.rate_hz))
            if n_ramp > 0:
                ramp = np.linspace(last_pa, 0.0, n_ramp + 1)[1:]
                # One reference swap: the loop reads the new array from its next tick on.
                self.values_pa = np.concatenate([self.values_pa[: i + 1], ramp])
                self.get_logger().warning(
                    f"stopped mid-signal at {last_pa / 1e5:.2f} bar: ramping down over "
                    f"{n_ramp / self.rate_hz:.2f} s"
                )
                self.done.wait(n_ramp / self.rate_hz + 1.0)
        self.loop.stop()


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run catheter_control excite``; exits when the signal is sent."""
    nodes: list[ExciteNode] = []

    def build() -> ExciteNode:
        nodes.append(ExciteNode())
        return nodes[0]

    done_at: list[float] = []

    def finished(node: ExciteNode) -> bool:
        # Linger after the last sample: best-effort messages still in flight would be lost
        # with the participant, and the recorder would miss the end of the signal.
        if node.done.is_set() and not done_at:
            done_at.append(time.monotonic())
        return bool(done_at) and time.monotonic() - done_at[0] > _LINGER_S

    code = run_node(build, args, until=finished)  # type: ignore[arg-type]
    if code == 0 and nodes and nodes[0].failure:
        rclpy.logging.get_logger("excite").fatal(nodes[0].failure)
        code = 3
    elif code == 0 and nodes:
        node = nodes[0]
        skipped = node.values_pa.size - node.published
        said = f"signal {node.signal_name!r} sent"
        if skipped > 0:
            # Nothing lost silently: the plant held the previous command through each.
            node.get_logger().warning(
                f"{said}: {skipped} of {node.values_pa.size} samples skipped "
                f"({skipped / node.values_pa.size:.2%}): the loop missed their deadlines"
            )
        else:
            node.get_logger().info(f"{said}, every sample on time")
    if code:
        raise SystemExit(code)


if __name__ == "__main__":
    main()
