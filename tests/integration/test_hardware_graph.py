"""The real driver nodes against the emulated rig, as separate processes over DDS and ptys.

``valve_driver`` and ``laser_angle`` talk the real wire protocols to the emulated devices
(``python -m catheter_driver.emulators.rig``: Keller transmitter, DAC bridge, laser ADC
bridge around the simulated plant, in real time). The same open-loop excitation must give the
same bag as ``sim_hardware``, and the faults a real rig has (commands stop, a device stops
answering, a cable is pulled) must vent the valve in time, be named on /diagnostics, and heal.
"""

from __future__ import annotations

import json
import math
import queue
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from fault_log import FaultRecord
from graph_utils import (
    SLACK_SENSOR_TIMEOUT_S,
    Children,
    Probe,
    diagnostic_values,
    node_argv,
    recorder_values,
    statuses,
    wait_for_recorder,
)
from sensor_msgs.msg import FluidPressure, JointState

from catheter_control.bringup import NodeSpec, driver_specs, sim_graph_specs
from catheter_models.bag import BagData, StampedSeries, load_bag
from catheter_models.contract import (
    DIAGNOSTICS,
    PRESSURE_COMMAND,
    PRESSURE_MEASURED,
    TIP_ANGLE,
    TIP_DISTANCE,
    qualify,
)
from catheter_models.geometry import Calibration
from catheter_models.plant import PlantConfig
from catheter_models.signals import get_preset
from catheter_ros import messages
from catheter_ros.qos import RECORD, STREAM

pytestmark = [
    pytest.mark.slow,
    # lark (imported by the ROS message tooling) still uses sre_parse; not ours.
    pytest.mark.filterwarnings("ignore:module 'sre_:DeprecationWarning"),
]

RATE_HZ = 250.0
PERIOD_S = 1.0 / RATE_HZ
SIGNAL = "train_zero_f0.4"
TAIL_S = 0.5
STRAIGHT_DISTANCE_M = float(PlantConfig.thesis_rig().rig["straight_distance_m"])
SENSOR_TOPICS = [qualify(s) for s in (PRESSURE_MEASURED, TIP_DISTANCE, TIP_ANGLE)]
VALVE_DRIVER = "catheter/valve_driver"
WATCHDOG_S = 0.1  # valve_driver's default watchdog_s
FAILSAFE_S = 0.2  # the emulated DAC bridge's default failsafe_timeout_s
RECONNECT_S = 1.0  # valve_driver's default reconnect_period_s
VENTED_PA = 2.0e3  # 0.02 bar: the muscle is vented (truth, noise-free)


# -- the emulated rig as a child process, with its stdin command channel ----------------------
class RigProcess:
    """``python -m catheter_driver.emulators.rig`` with faults injected through stdin.

    Args:
        log_dir: its stderr goes to ``<log_dir>/rig.log`` (shown with the other logs on failure).
    """

    def __init__(self, log_dir: Path) -> None:
        log_dir.mkdir(parents=True, exist_ok=True)
        with (log_dir / "rig.log").open("wb") as err:
            self.proc = subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "catheter_driver.emulators.rig",
                    "--keller-pty",
                    "--dac-pty",
                    "--adc-pty",
                ],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=err,
                text=True,
            )
        self._lines: queue.Queue[str] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()
        try:
            self.ports: dict[str, dict[str, Any]] = json.loads(self._next_line(30.0))
        except BaseException:
            self.close()
            raise

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self._lines.put(line)

    def _next_line(self, timeout_s: float) -> str:
        try:
            return self._lines.get(timeout=timeout_s)
        except queue.Empty:
            raise AssertionError(
                f"the emulated rig said nothing within {timeout_s:g} s (exit {self.proc.poll()})"
            ) from None

    def send(self, command: dict[str, Any]) -> dict[str, Any]:
        """One command; its acknowledgement (asserted ok)."""
        assert self.proc.stdin is not None
        self.proc.stdin.write(json.dumps(command) + "\n")
        self.proc.stdin.flush()
        reply: dict[str, Any] = json.loads(self._next_line(5.0))
        assert reply.get("ok"), reply
        return reply

    def state(self) -> dict[str, Any]:
        """The plant's truth and the devices' state (see ``emulators/rig.py``)."""
        state: dict[str, Any] = self.send({"query": "state"})["state"]
        return state

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(10.0)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10.0)


@pytest.fixture
def rig(tmp_path: Path) -> Iterator[RigProcess]:
    """The emulated rig. Request it before ``children`` so that it stops after the drivers."""
    r = RigProcess(tmp_path / "logs")
    try:
        yield r
    finally:
        r.close()


def _calibration(path: Path) -> Path:
    """The laser taken as zeroed at the plant's straight-tip distance, as sim_hardware is."""
    Calibration(STRAIGHT_DISTANCE_M, 0.0, 0, "test: the plant's straight_distance_m").save(path)
    return path


def _specs(rig: RigProcess, tmp_path: Path, **valve_params: object) -> dict[str, NodeSpec]:
    specs = {s.name: s for s in driver_specs(rig.ports, _calibration(tmp_path / "cal.json"))}
    specs["valve_driver"].params.update(valve_params)
    return specs


# -- 2a: the same excitation through sim_hardware and through the real drivers --------------
def _signal_pa() -> np.ndarray:
    """What excite sends for SIGNAL, sample by sample (without the ramp and tail)."""
    return np.asarray(get_preset(SIGNAL).generate(RATE_HZ).values_si, dtype=float)


def _command_origin_s(bag: BagData, signal_pa: np.ndarray) -> float:
    """Bag time [s] of the signal's first sample, as excite stamps it.

    Not simply the bag's first pressure/command: excite never sends sample 0 (the tick that
    sees its first subscriber only marks the start), and a recorder that matched excite late
    misses more (with the excite executable: up to 465 samples, see _excite). The
    first recorded command is sample m of the signal; m is found by matching the recorded
    values (excite stamps sample i at its deadline, first stamp + i periods, even across
    skipped ticks, so the stamps give each sample's index).
    """
    cmd = bag.pressure_command
    n = min(len(cmd), 500)
    index = np.round((cmd.t_s[:n] - cmd.t_s[0]) / PERIOD_S).astype(int)
    candidates = np.arange(signal_pa.size - index[-1])
    errors = np.max(np.abs(cmd.values[:n] - signal_pa[candidates[:, None] + index]), axis=1)
    m = int(np.argmin(errors))
    assert errors[m] < 1.0, f"pressure/command does not match {SIGNAL}: {errors[m]:.1f} Pa"
    print(f"{bag.path.name}: the first recorded pressure/command is sample {m}")
    return float(cmd.t_s[0]) - m * PERIOD_S


def _check_rates(bag: BagData, label: str, span_s: tuple[float, float]) -> None:
    """Each contract stream at 250 Hz over the excitation (``span_s``, bag time)."""
    series: dict[str, StampedSeries | None] = {
        "pressure/command": bag.pressure_command,
        "pressure/measured": bag.pressure_measured,
        "tip/angle": bag.tip_angle,
        "tip/distance": bag.tip_distance,
    }
    for name, s in series.items():
        assert s is not None, f"{label}: no {name}"
        start_s = max(span_s[0], float(s.t_s[0]))
        t = s.t_s[(s.t_s >= start_s) & (s.t_s <= span_s[1])]
        expected = (span_s[1] - start_s) * RATE_HZ
        median_ms = float(np.median(np.diff(t))) * 1e3
        print(f"{label} {name}: {t.size} samples of {expected:.0f}, median {median_ms:.3f} ms")
        # valve_driver stamps a reading at the middle of its RS485 round trip, so its periods
        # jitter; the median is still one period.
        assert abs(median_ms - 4.0) < 0.2, f"{label} {name}: median period {median_ms:.3f} ms"
        assert t.size <= expected + 2, f"{label} {name}: {t.size} > {expected:.0f}"
        # Nothing lost silently: what the window lacks, the recorder counted as lost.
        lost = json.loads(bag.custom_data.get("samples_lost", "{}")).get(qualify(name), 0)
        assert expected - t.size <= lost + 2, (
            f"{label} {name}: {t.size} of {expected:.0f}, {lost} said lost"
        )
        if name == "pressure/command":
            continue  # what excite sent on time: checked against its ticks by the caller
        if name == "pressure/measured" and label == "emu":
            # Polled: a poll the driver's loop skips on a busy host is a sample never taken
            # (counted above). Past 10 %, the machine is too busy for this comparison.
            assert t.size >= 0.90 * expected, f"{label} {name}: {t.size} of {expected:.0f}"
        else:
            # Sampled on the rig's own clock and sent reliably: every one is in the bag.
            assert t.size >= expected - 2, f"{label} {name}: {t.size} of {expected:.0f}"


def _on_axis(series: StampedSeries, origin_s: float) -> tuple[np.ndarray, np.ndarray]:
    return series.t_s - origin_s, series.values


def _best_lag_s(
    ta: np.ndarray, a: np.ndarray, tb: np.ndarray, b: np.ndarray, span: tuple[float, float]
) -> tuple[float, float]:
    """Shift of b (positive: b late) minimising the RMS difference, and that RMS."""
    keep = (ta >= span[0] + 0.05) & (ta <= span[1] - 0.05)
    best = (0.0, math.inf)
    for lag_s in np.arange(-0.01, 0.0201, 0.0005):
        rms = float(np.sqrt(np.mean((a[keep] - np.interp(ta[keep] + lag_s, tb, b)) ** 2)))
        if rms < best[1]:
            best = (float(lag_s), rms)
    return best


def _wait_streams(probe: Probe, timeout_s: float) -> None:
    """The recorder hears every sensor stream's publisher, and data flows (drivers active)."""
    probe.subscribe(DiagnosticArray, DIAGNOSTICS.name, 10)
    angle = probe.subscribe(JointState, TIP_ANGLE.name, RECORD)
    measured = probe.subscribe(FluidPressure, PRESSURE_MEASURED.name, RECORD)
    wait_for_recorder(probe, SENSOR_TOPICS, timeout_s=timeout_s)
    # The drivers autostart once their devices answer: wait for data, not just publishers.
    flowing = probe.spin_until(lambda: len(angle) > 25 and len(measured) > 25, timeout_s)
    assert flowing, f"no sensor data: {len(angle)} angles, {len(measured)} pressures"


EXCITE_HELPER = Path(__file__).with_name("excite_when_heard.py")


def _excite(children: Children, probe: Probe, label: str, params: dict[str, object]) -> None:
    """Send the whole signal as ``excite`` does, started once everyone hears it.

    Not the ``excite`` executable: it starts its signal as soon as its *first* subscriber on
    pressure/command matches, and the others may match much later. Measured here with the
    emulated graph running, for a fresh process publishing on pressure/command: the second
    subscriber matched 0.003 to 2.4 s after the first (8 tries). With excite as its own
    process, valve_driver missed the first 2.5 s of the signal in one run of three (the bag
    then holds commands the rig never got) and the recorder missed up to 1.9 s in another.
    So ``excite_when_heard.py`` builds excite's node and starts it only when every subscriber
    the probe counts has matched it and the recorder says it hears it; the test then checks
    that the rig counted every command the recorder kept. It runs as a process of its own:
    in the pytest process (as it once did) its loop skipped 1.5 % of its ticks in a CI run.

    ``probe`` must be subscribed to /diagnostics (it watches the recorder).
    """
    cmd = qualify(PRESSURE_COMMAND)
    # The rig's streams reaching the probe does not mean the probe has discovered the
    # rig's and the recorder's command subscriptions yet: each endpoint is announced on its
    # own (a clean-clone CI run counted 1 of 2 here, with both nodes up).
    probe.spin_until(lambda: probe.node.count_subscribers(cmd) >= 2, 20.0)
    subscribers = probe.node.count_subscribers(cmd)
    assert subscribers >= 2, f"{subscribers} subscribers on {cmd}: rig and recorder?"
    heard_before = int(recorder_values(probe).get(f"publishers {cmd}", "0"))
    argv = node_argv("catheter_control.excite_node", params)
    argv = [
        sys.executable,
        str(EXCITE_HELPER),
        "--subscribers",
        str(subscribers),
        "--heard-before",
        str(heard_before),
        "--timeout-s",
        "60",
        *argv[argv.index("--ros-args") :],
    ]
    done = children.run(f"excite_{label}", argv, timeout_s=120.0)
    assert done.returncode == 0, (
        f"excite ({label}): exit {done.returncode}\n{done.stdout}\n{done.stderr}"
    )
    print(f"excite ({label}): {done.stdout.strip().splitlines()[-1]}")


def _fresh_diagnostics(probe: Probe, node: str) -> dict[str, str]:
    """``node``'s first /diagnostics values published from now on."""
    now_ns = probe.node.get_clock().now().nanoseconds

    def latest() -> dict[str, str] | None:
        fresh = [
            s
            for m in probe.received.get(DIAGNOSTICS.name, [])
            if messages.ns_from_time(m.msg.header.stamp) > now_ns
            for s in m.msg.status
            if s.name == node
        ]
        return diagnostic_values(fresh[-1]) if fresh else None

    probe.spin_until(lambda: latest() is not None, 3.0)
    values = latest()
    assert values is not None, f"no /diagnostics from {node} after the excitation"
    return values


@pytest.mark.parametrize(
    ("module", "param", "value", "range_text"),
    [
        ("catheter_driver.valve_driver_node", "watchdog_s", -1.0, "[0.01, 5]"),
        ("catheter_driver.laser_angle_node", "rate_hz", -1.0, "[10, 5000]"),
    ],
)
def test_driver_refuses_out_of_range_parameter_with_exit_2(
    children: Children, module: str, param: str, value: float, range_text: str
) -> None:
    """A refused parameter is exit 2 with the reason, not a crash in the half-built node.

    rclpy destroys a node whose constructor raised when its context shuts down; the valve
    driver's destroy_node read attributes set after the parameters and turned the refusal
    into an AttributeError and exit 1. No devices are needed: the refusal comes first.
    """
    run = children.run(module, node_argv(module, {param: value}), timeout_s=30.0)
    output = run.stdout + run.stderr
    assert run.returncode == 2, f"exit {run.returncode}:\n{output}"
    assert param in output and range_text in output, output
    assert "Traceback" not in output, output


@pytest.mark.timeout(900)  # 45-80 s idle; minutes beside two busy loops
def test_drivers_match_sim_hardware(rig: RigProcess, children: Children, tmp_path: Path) -> None:
    # One graph after the other: both at once (on two domains) would take 20 s less, but on
    # this 2-core machine the emulated graph alone keeps one core busy (recorder, drivers and
    # rig at 250 Hz), and together they doubled the angle difference (0.135 vs 0.064 deg RMS,
    # 0.7 deg peaks in the first seconds): CPU contention, not what this test is about.
    t0 = time.monotonic()
    # No lead-in: this test waits for every subscriber itself and matches the recorded
    # commands sample by sample against the preset.
    excite: dict[str, object] = {"signal": SIGNAL, "tail_s": TAIL_S, "lead_in_s": 0.0}
    received: dict[str, int] = {}
    # (i) sim_hardware + recorder.
    sim_bag = tmp_path / "sim_bag"
    sim = children.graph(
        sim_graph_specs(sim_bag, {"source": "test_hardware_graph sim"}, with_compensator=False),
        log_subdir="sim",
    )
    with Probe(children.domain_id) as probe:
        _wait_streams(probe, 30.0)
        _excite(children, probe, "sim", excite)
        received["sim"] = int(
            _fresh_diagnostics(probe, "catheter/sim_hardware")["commands_received"]
        )
    assert sim.stop(timeout_s=15.0) == {"sim_hardware": 0, "recorder": 0}
    t1 = time.monotonic()

    # (ii) emulated rig + valve_driver + laser_angle + compensator + recorder.
    emu_bag = tmp_path / "emu_bag"
    specs = _specs(rig, tmp_path)
    # About the drivers' data, not the sensor timeout: a clean-clone CI run beside two busy
    # loops saw pressure/measured quiet for 104 ms and the triangle stopped part-way.
    recorder, _sim, compensator = sim_graph_specs(
        emu_bag,
        {"source": "test_hardware_graph emulated rig"},
        compensator_params={"sensor_timeout_s": SLACK_SENSOR_TIMEOUT_S},
    )
    emu = children.graph(
        [recorder, specs["valve_driver"], specs["laser_angle"], compensator],
        log_subdir="emu",
    )
    with Probe(children.domain_id) as probe:
        _wait_streams(probe, 30.0)
        _excite(children, probe, "emu", excite)
        driver = _fresh_diagnostics(probe, VALVE_DRIVER)
        received["emu"] = int(driver["commands_received"])
        state = rig.state()
        print(f"rig: {state['plant_steps']} samples, {state['steps_caught_up']} caught up late")
    t2 = time.monotonic()

    # The compensator on the real drivers: the sim graph test's triangle and bound.
    csv = tmp_path / "triangle.csv"
    csv.write_text("t_s,angle_deg\n0,0\n2.5,15\n5,0\n")
    run = children.run(
        "follow_trajectory",
        [
            sys.executable,
            "-m",
            "catheter_control.follow_trajectory",
            "--file",
            str(csv),
            "--out",
            str(tmp_path / "run"),
            "--no-progress",
            "--timeout-s",
            "30",
        ],
        timeout_s=60.0,
    )
    assert run.returncode == 0, f"exit {run.returncode}\n{run.stdout}\n{run.stderr}"
    report = json.loads((tmp_path / "run" / "report.json").read_text())
    codes = emu.stop(timeout_s=15.0)
    assert codes == {"compensator": 0, "laser_angle": 0, "valve_driver": 0, "recorder": 0}, (
        f"{codes}\n"
        + "\n".join(f"--- {n} ---\n{children.log(n, 'emu')[-3000:]}" for n in codes if codes[n])
    )
    t3 = time.monotonic()
    print(f"sim {t1 - t0:.1f} s, emulated {t2 - t1:.1f} s, follow_trajectory {t3 - t2:.1f} s")

    signal_pa = _signal_pa()
    bags = {"sim": load_bag(sim_bag), "emu": load_bag(emu_bag)}
    origin = {k: _command_origin_s(b, signal_pa) for k, b in bags.items()}
    for label, bag in bags.items():
        t_cmd = bag.pressure_command.t_s
        t_cmd = t_cmd[t_cmd < origin[label] + 15.0]  # excite's, not follow_trajectory's
        ticks = round((t_cmd[-1] - t_cmd[0]) / PERIOD_S) + 1
        print(
            f"{label}: {t_cmd.size} commands of {ticks} ticks recorded, {received[label]} "
            "received by the rig"
        )
        # The rig got what the recorder kept (best effort may drop a few on either path); a
        # rig that missed the start of the signal would be hundreds short.
        assert received[label] >= t_cmd.size - 10, (label, t_cmd.size, received[label])
        # Both plants must get the same input, so excite must keep its deadlines: a skipped
        # tick holds the previous set-point 4 ms longer in one run only. Quiet machine: 0 to
        # 6 of 3515 skipped. With another pytest on the two cores: up to 108 (3 %), and then
        # the angles differed by 0.24 deg RMS. Past 1 %, say so rather than compare.
        assert t_cmd.size >= 0.99 * ticks, (
            f"{label}: excite sent {t_cmd.size} of {ticks} commands on time; the machine is "
            "too busy for this comparison"
        )
    duration_s = signal_pa.size * PERIOD_S
    for label, bag in bags.items():
        _check_rates(bag, label, (origin[label], origin[label] + duration_s))

    # Same command, sample for sample, on both axes.
    cmd = {k: _on_axis(b.pressure_command, origin[k]) for k, b in bags.items()}
    for label, (t, v) in cmd.items():
        keep = t < duration_s - PERIOD_S / 2
        index = np.round(t[keep] / PERIOD_S).astype(int)
        assert np.allclose(v[keep], signal_pa[index], atol=1.0), label

    # What the two runs may differ by, and why (numbers: 6 runs of this test, one at a time).
    # Noise: every sample carries its own sensor noise in each run: laser 0.02 mm (0.04 deg)
    # and transmitter 300 Pa std. The emulated trace is interpolated between two of its
    # samples (2/3 of the variance on average), so the difference has a floor of
    # sqrt(1 + 2/3) sigma = 0.052 deg and 390 Pa RMS.
    # Timing: sim_hardware applies a command at its next 4 ms plant step. On the emulated
    # rig it waits for valve_driver's next control tick (<= 4 ms), the SET round trip over the
    # pty (< 1 ms) and the rig's next plant step (<= 4 ms). Each of these 250 Hz loops runs at
    # a random but fixed phase, so the emulated traces lag by a constant in (-4, +8) ms, set
    # anew each run. pressure/measured lags further by the age of the plant sample the Keller
    # emulator serves (< 4 ms), as valve_driver stamps the middle of its round trip: (-4, +12).
    # Measured, as the shift that best aligns the traces (0.5 ms steps): tip/angle -1 to
    # 5.5 ms, pressure/measured 3 to 8.5 ms. Windows: the ranges above +-1 ms (0.5 ms grid,
    # and the minimum is shallow).
    # At that shift the difference is noise plus stamp jitter: measured 0.053 to 0.060 deg
    # and 405 to 462 Pa; with another pytest sharing the two cores (excite still on time)
    # 0.073 to 0.080 deg and 528 Pa; with both graphs at once 0.125 deg and 552 Pa (see
    # above). Bounds 0.1 deg and 600 Pa: 1.5 to 2 x the noise floor, the loaded case inside.
    # Unaligned, a lag costs (RMS rate of change) x lag, about 19 deg/s and 120 kPa/s here:
    # measured 0.062 to 0.101 deg and 548 to 1080 Pa. Bounds: the worst lag of the windows
    # (9 and 13 ms) on top of the aligned bounds, 0.2 deg and 1700 Pa (loaded: 0.08 deg,
    # 1193 Pa).
    # The mean difference shows a bias a lag cannot (the signal starts and ends at rest):
    # measured |mean| <= 0.007 deg and <= 18 Pa. 0.03 deg is 15 um of laser reference (a
    # calibration off by that fails); 100 Pa is under two DAC steps (60 Pa each).
    # A busy host stretches valve_driver's RS485 round trip, and a reading is stamped at the
    # middle of it: true anywhere within it, so its stamp is off by RMS round trip / sqrt(12)
    # (uniform), which costs (RMS rate of change) x that in Pa, beside the sensor noise. The
    # driver reports the round trip on /diagnostics; the aligned bound is widened by what it
    # reported, no more (idle: 0.5 to 1 ms RMS, ~20 Pa; the 663 and 737 Pa failures of the
    # 600 Pa bound came on hosts running a second test suite).
    rtt_rms_s = float(driver["transmitter_round_trip_rms_ms"]) * 1e-3
    rate_rms_pa_s = float(np.sqrt(np.mean(np.diff(signal_pa) ** 2))) / PERIOD_S
    stamp_pa = rate_rms_pa_s * rtt_rms_s / math.sqrt(12.0)
    print(
        f"valve_driver round trip RMS {rtt_rms_s * 1e3:.2f} ms, p99 "
        f"{driver['transmitter_round_trip_p99_ms']} ms: stamps cost {stamp_pa:.0f} Pa RMS at "
        f"{rate_rms_pa_s / 1e3:.0f} kPa/s"
    )
    bounds = {
        "tip/angle": {"lag_ms": (-5.0, 9.0), "rms_at_lag": 0.1, "rms": 0.2, "mean": 0.03},
        "pressure/measured": {
            "lag_ms": (-5.0, 13.0),
            "rms_at_lag": math.hypot(600.0, 1.5 * stamp_pa),
            "rms": 1700.0,
            "mean": 100.0,
        },
    }
    results: dict[str, dict[str, float]] = {}
    for name, getter, unit_scale in (
        ("tip/angle", lambda b: b.tip_angle, math.degrees(1.0)),
        ("pressure/measured", lambda b: b.pressure_measured, 1.0),
    ):
        ta, a = _on_axis(getter(bags["sim"]), origin["sim"])
        tb, b = _on_axis(getter(bags["emu"]), origin["emu"])
        span = (max(ta[0], tb[0], 0.0), min(ta[-1], tb[-1], duration_s))
        assert span[1] - span[0] > duration_s - 0.1, (name, span)
        keep = (ta >= span[0]) & (ta <= span[1])
        diff = (a[keep] - np.interp(ta[keep], tb, b)) * unit_scale
        lag_s, lag_rms = _best_lag_s(ta, a, tb, b, span)
        got = {
            "rms": float(np.sqrt(np.mean(diff**2))),
            "mean": float(np.mean(diff)),
            "max": float(np.max(np.abs(diff))),
            "lag_ms": lag_s * 1e3,
            "rms_at_lag": lag_rms * unit_scale,
        }
        print(f"{name}: " + ", ".join(f"{k} {v:.4g}" for k, v in got.items()))
        results[name] = got
    for name, got in results.items():
        bound = bounds[name]
        low, high = bound["lag_ms"]
        assert low <= got["lag_ms"] <= high, (name, got)
        assert got["rms_at_lag"] <= bound["rms_at_lag"], (name, got)
        assert got["rms"] <= bound["rms"], (name, got)
        assert abs(got["mean"]) <= bound["mean"], (name, got)

    # The sim graph test's bound for this triangle (test_graph.py: measured 1.1 to 1.6 deg
    # there, 8.7 deg for a rig that does not move). Measured here: 1.07 to 1.11 deg.
    rmse = report["overall"]["rmse_deg"]
    print(f"follow_trajectory on the real drivers: RMSE {rmse:.2f} deg")
    assert rmse < 3.0, report["overall"]


# -- 2b: faults, with valve_driver on the emulated rig --------------------------------------
class CommandStream:
    """pressure/command at 250 Hz from a thread of the test, as a compensator sends it."""

    def __init__(self, probe: Probe) -> None:
        self.pub = probe.node.create_publisher(FluidPressure, PRESSURE_COMMAND.name, STREAM)
        self._clock = probe.node.get_clock()
        self._gauge_pa: float | None = None
        self.last_sent_s: float | None = None
        """Monotonic time of the last command published [s]."""
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def send(self, gauge_pa: float | None) -> None:
        """Send ``gauge_pa`` from now on; None: stop sending (the last time is kept)."""
        with self._lock:
            self._gauge_pa = gauge_pa

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)

    def _run(self) -> None:
        next_s = time.monotonic()
        while not self._stop.is_set():
            with self._lock:
                gauge_pa = self._gauge_pa
                if gauge_pa is not None:
                    stamp = self._clock.now().nanoseconds
                    self.pub.publish(messages.fluid_pressure(gauge_pa, stamp, ""))
                    self.last_sent_s = time.monotonic()
            next_s += PERIOD_S
            time.sleep(max(0.0, next_s - time.monotonic()))


class FaultBench:
    """valve_driver on the emulated rig, a probe on its topics, and a command stream."""

    def __init__(self, rig: RigProcess, probe: Probe) -> None:
        self.rig = rig
        self.probe = probe
        self.measured = probe.subscribe(FluidPressure, PRESSURE_MEASURED.name, RECORD)
        self.diags = probe.subscribe(DiagnosticArray, DIAGNOSTICS.name, 10)
        self.stream = CommandStream(probe)

    def wait_ready(self, timeout_s: float = 30.0) -> None:
        ready = self.probe.spin_until(
            lambda: (
                len(self.measured) > 25
                and self.stream.pub.get_subscription_count() > 0
                and bool(self.statuses())
            ),
            timeout_s,
        )
        assert ready, f"valve_driver not up: {len(self.measured)} readings, {self.statuses()[-1:]}"

    def statuses(self, since: int = 0) -> list[DiagnosticStatus]:
        return statuses(self.diags[since:], VALVE_DRIVER)

    def wait_status(
        self, predicate: Callable[[DiagnosticStatus], bool], timeout_s: float, since: int = 0
    ) -> DiagnosticStatus:
        """The first valve_driver status (among /diagnostics from index ``since``) that holds."""

        def found() -> DiagnosticStatus | None:
            return next((s for s in self.statuses(since) if predicate(s)), None)

        self.probe.spin_until(lambda: found() is not None, timeout_s)
        status = found()
        assert status is not None, (
            f"no such valve_driver status within {timeout_s:g} s; last: "
            f"{[(s.message, diagnostic_values(s)) for s in self.statuses(since)[-1:]]}"
        )
        return status

    def wait_rig(self, predicate: Callable[[dict[str, Any]], bool], timeout_s: float) -> dict:
        """Poll the rig's truth (every ~10 ms, spinning the probe meanwhile) until it holds."""
        end = time.monotonic() + timeout_s
        while True:
            state = self.rig.state()
            if predicate(state) or time.monotonic() > end:
                break
            self.probe.spin_for(0.01)
        assert predicate(state), f"rig state after {timeout_s:g} s: {state}"
        return state

    def follow(self, gauge_pa: float) -> dict[str, Any]:
        """Command ``gauge_pa`` until the muscle holds it (truth, within 1 kPa)."""
        self.stream.send(gauge_pa)
        return self.wait_rig(
            lambda s: s["muscle_pa"] is not None and abs(s["muscle_pa"] - gauge_pa) < 1.0e3, 5.0
        )

    def readings_after(self, t_s: float) -> list[float]:
        """pressure/measured [Pa gauge] received after monotonic ``t_s``."""
        return [m.msg.fluid_pressure - 101325.0 for m in self.measured if m.mono_s > t_s]

    def readings_between(self, start_s: float, end_s: float) -> np.ndarray:
        """pressure/measured [Pa gauge] received in [start_s, end_s] (monotonic; waits)."""
        self.probe.spin_until(lambda: time.monotonic() > end_s + 0.05, end_s - start_s + 1.0)
        return np.array(
            [m.msg.fluid_pressure - 101325.0 for m in self.measured if start_s <= m.mono_s <= end_s]
        )


@pytest.fixture
def bench(rig: RigProcess, children: Children, tmp_path: Path) -> Iterator[FaultBench]:
    spec = _specs(rig, tmp_path)["valve_driver"]
    children.start("valve_driver", node_argv(spec.module, spec.params))
    with Probe(children.domain_id) as probe:
        b = FaultBench(rig, probe)
        try:
            b.wait_ready()
            yield b
        finally:
            b.stream.close()


def _values(status: DiagnosticStatus) -> dict[str, str]:
    return diagnostic_values(status)


@pytest.mark.fault(
    "pressure commands stop (valve_driver on the emulated DAC bridge)",
    safe="valve_driver's watchdog vents the valve",
    category="drivers",
)
def test_commands_stop_vents_within_watchdog(bench: FaultBench, fault: FaultRecord) -> None:
    bench.follow(2.0e5)
    bench.probe.spin_for(0.3)
    n_diag = len(bench.diags)
    bench.stream.send(None)
    last_sent_s = bench.stream.last_sent_s
    assert last_sent_s is not None
    state = bench.wait_rig(
        lambda s: (s["vented_at_s"] or 0.0) > last_sent_s and s["muscle_pa"] < VENTED_PA, 2.0
    )
    delay_s = state["vented_at_s"] - last_sent_s
    print(f"vented {delay_s * 1e3:.1f} ms after the last command")
    # The watchdog trips at the first control tick (every 4 ms) more than 100 ms after the
    # last command arrived (DDS latency after it was sent), then the SET of 0 crosses the
    # pty (< 1 ms): 100 to 105 ms. Measured 101.6 to 103.9 ms; the bound allows a control
    # tick 25 ms late on a loaded 2-core machine.
    fault.safe_after(delay_s)
    fault.check("vent", WATCHDOG_S <= delay_s <= WATCHDOG_S + 0.03, f"{delay_s * 1e3:.1f} ms")
    # valve_driver kept writing 0 every tick, so the bridge's own fail-safe never tripped.
    bench.probe.spin_for(2 * FAILSAFE_S)
    assert bench.rig.state()["devices"]["dac_serial"]["failsafe"]["trips"] == 0
    status = bench.wait_status(lambda s: _values(s)["state"] == "watchdog", 3.0, n_diag)
    assert status.level == DiagnosticStatus.WARN
    fault.check(
        "reported",
        "commands stopped for more than 100 ms" in status.message
        and _values(status)["watchdog_trips"] == "1",
        status.message,
    )
    # The transmitter saw the vent too (noise: 300 Pa std).
    vented = bench.readings_between(state["t_s"], state["t_s"] + 0.2)
    assert vented.size > 25 and np.all(vented < VENTED_PA + 2.0e3), vented

    # Recovery: the next command is followed.
    n_diag = len(bench.diags)
    bench.follow(1.0e5)
    status = bench.wait_status(lambda s: _values(s)["state"] == "ok", 3.0, n_diag)
    assert status.level == DiagnosticStatus.OK


@pytest.mark.fault(
    "pressure transmitter stops replying (Keller serial emulator)",
    safe="reported as link down; the valve keeps following; reconnects when it answers",
    category="drivers",
)
def test_transmitter_silent_reported_and_recovered(bench: FaultBench, fault: FaultRecord) -> None:
    bench.follow(1.5e5)
    n_diag = len(bench.diags)
    t_fault = bench.rig.send({"fault": "no_reply", "device": "keller_serial"})["t_s"]
    status = bench.wait_status(
        lambda s: _values(s)["transmitter_link"].startswith("down"), 4.0, n_diag
    )
    values = _values(status)
    print(f"transmitter down: {status.message!r}, {values['transmitter.timeouts']} timeouts")
    # Named on the status itself, not only among the values: pressure/measured has stopped.
    fault.check(
        "reported",
        status.level == DiagnosticStatus.ERROR
        and "transmitter link down" in status.message
        and "no reply" in status.message,
        status.message,
    )
    fault.safe_after(0.0)  # the valve was never affected: it holds its commanded pressure
    assert status.message.count(bench.rig.ports["keller_serial"]["port"]) == 1, status.message
    assert "no reply" in values["transmitter_link"], values
    assert int(values["transmitter.timeouts"]) >= 5, values  # MAX_CONSECUTIVE_TIMEOUTS
    late = bench.readings_after(t_fault + 0.15)  # a reply in flight at the fault still lands
    assert not late, f"{len(late)} pressure/measured after the transmitter fell silent"
    # The control tick never waits on the transmitter: the valve still follows.
    assert abs(bench.rig.state()["command_pa"] - 1.5e5) < 100.0

    n_diag = len(bench.diags)
    t_clear = bench.rig.send({"fault": "none", "device": "keller_serial"})["t_s"]
    assert bench.probe.spin_until(lambda: len(bench.readings_after(t_clear)) > 25, 2 * RECONNECT_S)
    first_s = next(m.mono_s for m in bench.measured if m.mono_s > t_clear)
    print(f"pressure/measured again {(first_s - t_clear) * 1e3:.0f} ms after the fault cleared")
    # valve_driver re-opens the transmitter every reconnect_period_s (1 s); the first try after
    # the fault cleared succeeds (F48 + F73 round trips, milliseconds). Measured 515 to 527 ms.
    assert first_s - t_clear <= RECONNECT_S + 0.2
    readings = np.array(bench.readings_after(t_clear))
    assert np.all(np.abs(readings - 1.5e5) < 3.0e3), readings  # 10 sigma of 300 Pa
    status = bench.wait_status(lambda s: _values(s)["transmitter_link"] == "up", 3.0, n_diag)
    assert _values(status)["transmitter.reconnects"] == "1", _values(status)
    assert status.level == DiagnosticStatus.OK, status.message


@pytest.mark.fault(
    "valve's serial link unplugged (DAC bridge emulator)",
    safe="the bridge's own fail-safe vents; valve_driver reports and reconnects",
    category="drivers",
)
def test_unplugged_valve_vents_by_failsafe_and_reconnects(
    bench: FaultBench, fault: FaultRecord
) -> None:
    bench.follow(2.0e5)
    port = bench.rig.ports["dac_serial"]["port"]
    n_diag = len(bench.diags)
    t_unplug = bench.rig.send({"unplug": "dac_serial"})["t_s"]
    state = bench.wait_rig(
        lambda s: (
            s["devices"]["dac_serial"]["failsafe"]["trips"] >= 1 and s["muscle_pa"] < VENTED_PA
        ),
        2.0,
    )
    failsafe = state["devices"]["dac_serial"]["failsafe"]
    delay_s = state["vented_at_s"] - t_unplug
    silence_s = failsafe["tripped_at_s"] - failsafe["last_setpoint_s"]
    print(f"vented {delay_s * 1e3:.1f} ms after the unplug, {silence_s * 1e3:.1f} ms of silence")
    # The bridge's serving thread blocks until the fail-safe deadline, 200 ms after the last
    # SET, and vents then. Measured 200.1 to 200.5 ms of silence (the vent 198 to 199.4 ms
    # after the unplug: the last SET came a tick before it). The bound allows the thread to
    # wake 20 ms late on a loaded machine.
    assert FAILSAFE_S <= silence_s <= FAILSAFE_S + 0.02, failsafe
    fault.safe_after(delay_s)
    fault.check("vent", delay_s <= FAILSAFE_S + 0.02, f"{delay_s * 1e3:.1f} ms ({failsafe})")
    # The transmitter (still connected) saw the vent too (noise: 300 Pa std).
    vented = bench.readings_between(state["t_s"], state["t_s"] + 0.2)
    assert vented.size > 25 and np.all(vented < VENTED_PA + 2.0e3), vented

    status = bench.wait_status(lambda s: _values(s)["state"] == "link_down", 3.0, n_diag)
    down = status.level == DiagnosticStatus.ERROR and port in status.message
    fault.check("reported", down, status.message)
    assert _values(status)["valve_link"].startswith("down"), _values(status)

    n_diag = len(bench.diags)
    t_replug = bench.rig.send({"replug": "dac_serial"})["t_s"]
    state = bench.wait_rig(
        lambda s: (
            (s["last_command_s"] or 0.0) > t_replug
            and s["muscle_pa"] is not None
            and abs(s["muscle_pa"] - 2.0e5) < 1.0e3
        ),
        RECONNECT_S + 2.0,
    )
    back_s = state["last_command_s"] - t_replug
    print(f"following again {back_s * 1e3:.0f} ms after replug")
    # The valve link is retried every reconnect_period_s (1 s); the first retry after the
    # replug succeeds, then the set-point slews back to 2 bar (0.1 s at 20 bar/s). Measured
    # 146 to 163 ms (the retry schedule, fixed by the unplug, fell soon after the replug).
    assert back_s <= RECONNECT_S + 0.3, back_s
    status = bench.wait_status(lambda s: _values(s)["state"] == "ok", 3.0, n_diag)
    assert _values(status)["valve.reconnects"] == "1", _values(status)
    assert _values(status)["valve_link"] == "up"


@pytest.mark.fault(
    "kill -9 valve_driver while the valve holds 2 bar",
    safe="the DAC bridge's own fail-safe vents the valve",
    category="drivers",
)
def test_killed_valve_driver_is_vented_by_the_bridge_failsafe(
    bench: FaultBench, children: Children, fault: FaultRecord
) -> None:
    bench.follow(2.0e5)
    driver = children.procs["valve_driver"]
    t_kill = time.monotonic()
    driver.send_signal(signal.SIGKILL)
    state = bench.wait_rig(
        lambda s: (
            s["devices"]["dac_serial"]["failsafe"]["trips"] >= 1 and s["muscle_pa"] < VENTED_PA
        ),
        2.0,
    )
    failsafe = state["devices"]["dac_serial"]["failsafe"]
    silence_s = failsafe["tripped_at_s"] - failsafe["last_setpoint_s"]
    delay_s = state["vented_at_s"] - t_kill
    print(f"vented {delay_s * 1e3:.1f} ms after the kill, {silence_s * 1e3:.1f} ms of silence")
    fault.safe_after(delay_s)
    # Nothing is left to say so over ROS: the bridge's fail-safe is the layer that holds.
    fault.check(
        "vent",
        FAILSAFE_S <= silence_s <= FAILSAFE_S + 0.02 and delay_s <= FAILSAFE_S + 0.05,
        f"vented {delay_s * 1e3:.1f} ms after the kill ({failsafe})",
    )
    assert driver.wait(5.0) == -signal.SIGKILL
    fault.check(
        "range",
        bench.rig.state()["muscle_pa"] < VENTED_PA,
        f"muscle at {bench.rig.state()['muscle_pa']:.0f} Pa after the vent",
    )


# -- 2c: lifecycle transitions, driven through the real lifecycle services -------------------
def _change_state(bench: FaultBench, transition_id: int) -> bool:
    """Ask valve_driver for a lifecycle transition (lifecycle_msgs/ChangeState); its answer."""
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState

    client = bench.probe.node.create_client(ChangeState, f"/{VALVE_DRIVER}/change_state")
    assert bench.probe.spin_until(client.service_is_ready, 10.0), "no change_state service"
    future = client.call_async(ChangeState.Request(transition=Transition(id=transition_id)))
    assert bench.probe.spin_until(future.done, 10.0), f"transition {transition_id} hung"
    bench.probe.node.destroy_client(client)
    return bool(future.result().success)


def _state_label(bench: FaultBench) -> str:
    from lifecycle_msgs.srv import GetState

    client = bench.probe.node.create_client(GetState, f"/{VALVE_DRIVER}/get_state")
    assert bench.probe.spin_until(client.service_is_ready, 10.0), "no get_state service"
    future = client.call_async(GetState.Request())
    assert bench.probe.spin_until(future.done, 10.0)
    bench.probe.node.destroy_client(client)
    return str(future.result().current_state.label)


def test_lifecycle_transitions_leave_the_valve_vented(bench: FaultBench) -> None:
    from lifecycle_msgs.msg import Transition

    # Autostart brought the node to active; it follows commands.
    assert _state_label(bench) == "active"
    bench.follow(2.0e5)

    # Deactivate while commands keep streaming: the valve vents and stays vented.
    assert _change_state(bench, Transition.TRANSITION_DEACTIVATE)
    assert _state_label(bench) == "inactive"
    bench.wait_rig(lambda s: s["muscle_pa"] < VENTED_PA, 2.0)
    bench.probe.spin_for(0.5)
    assert bench.rig.state()["muscle_pa"] < VENTED_PA, "an inactive driver moved the valve"
    bench.wait_status(lambda s: "deactivated: valve vented" in s.message, 3.0)

    # Activate again: the still-streaming commands are followed.
    assert _change_state(bench, Transition.TRANSITION_ACTIVATE)
    bench.follow(2.0e5)

    # Deactivate and clean up: devices closed, valve vented; configure + activate recovers.
    assert _change_state(bench, Transition.TRANSITION_DEACTIVATE)
    assert _change_state(bench, Transition.TRANSITION_CLEANUP)
    assert _state_label(bench) == "unconfigured"
    bench.wait_rig(lambda s: s["muscle_pa"] < VENTED_PA, 2.0)
    assert _change_state(bench, Transition.TRANSITION_CONFIGURE)
    assert _change_state(bench, Transition.TRANSITION_ACTIVATE)
    assert _state_label(bench) == "active"
    bench.follow(2.0e5)
