"""The emulated rig: the simulated plant stepped in real time, behind emulated devices.

:class:`EmulatedRig` owns a :class:`~catheter_driver.sim_hardware.SimHardware` and steps it
at the plant's sample rate (250 Hz) on a deadline loop. Device emulators read its sensors
and feed it valve set-points, each over its own wire protocol.

Run as a program, it is a whole rig in a separate process for integration tests::

    python -m catheter_driver.emulators.rig --keller-pty --dac-pty --adc-pty

It prints one JSON line (flushed) mapping each emulated device's backend name to the
parameters that reach it, e.g.
``{"keller_serial": {"port": "/tmp/emulated-rig-x/keller_serial", "address": 1}}``,
ready for ``devices.factory`` (``make_transmitter("keller_serial", **line["keller_serial"])``),
then runs until SIGINT or SIGTERM. A pty device's ``port`` is a stable symlink to its
``/dev/pts/N`` (as a udev rule gives a real adapter), so a driver finds a replugged device
at the same path.

Faults are injected at run time by JSON commands on stdin, one per line; each is answered
by one JSON line on stdout, ``{"ack": <command>, "ok": true, "t_s": <monotonic>, ...}``
(``"ok": false, "error": ...`` if refused)::

    {"fault": "no_reply", "device": "keller_serial"}   # also bad_crc, garbage; "count": n
    {"fault": "none", "device": "keller_serial"}       # clear it
    {"unplug": "dac_serial"}    # close the pty (the driver's port dies), remove the symlink
    {"replug": "dac_serial"}    # a new pty; the symlink now points at it
    {"query": "state"}          # the plant's truth and each device's state, under "state"

``t_s`` and every time in the state are ``time.monotonic()`` of this process: the same
clock (CLOCK_MONOTONIC) as any other process on the machine, so a test can compare them
with its own.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import shutil
import signal
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, TextIO

from catheter_driver.sim_hardware import SimHardware
from catheter_models.errors import ParameterError
from catheter_models.plant import PlantConfig, PlantSample
from catheter_ros.rt_loop import DEFAULT_RT_PRIORITY, DeadlineLoop, set_process_realtime

if TYPE_CHECKING:
    from catheter_driver.emulators.base import Emulator
    from catheter_driver.emulators.pty_endpoint import PtyEndpoint

SampleListener = Callable[[PlantSample, float], None]
"""Called on the rig's thread with each new sample and its deadline [monotonic s]."""


class EmulatedRig:
    """The simulated plant in real time, with the emulators attached to it.

    Args:
        config: plant configuration; the thesis rig by default.
        max_pressure_pa: highest set-point applied, gauge [Pa]; the valve's maximum by default.
        command_timeout_s: vent after this long without a set-point [s]. A real regulator
            holds its last set-point forever (the driver node owns the watchdog), hence inf.
        rt_priority: SCHED_FIFO priority of the plant's loop, its emulators' threads 30 below
            (0: normal scheduling). Real devices have processors of their own; an emulator at
            normal priority shares the host with the graph it serves and, on 2 cores, was late
            on 15-23 % of its ticks. Where the OS refuses, :attr:`realtime` says why.
    """

    def __init__(
        self,
        config: PlantConfig | None = None,
        *,
        max_pressure_pa: float | None = None,
        command_timeout_s: float = math.inf,
        rt_priority: int = 0,
    ) -> None:
        self.rt_priority = rt_priority
        self.realtime = "not started"
        """``SCHED_FIFO <priority>`` once the rig runs real time, else why not."""
        config = config if config is not None else PlantConfig.thesis_rig()
        limit_pa = (
            max_pressure_pa if max_pressure_pa is not None else config.rig["valve_max_pressure_pa"]
        )
        self.hw = SimHardware(config, max_pressure_pa=limit_pa, command_timeout_s=command_timeout_s)
        self.config = config
        self.geometry = self.hw.plant.geometry
        self.ambient_pa = float(config.rig["ambient_pressure_pa"])
        self.sample_rate_hz = float(config.rig["sample_rate_hz"])
        self._listeners: list[SampleListener] = []
        self._emulators: list[Emulator] = []
        self._latest: PlantSample | None = None
        self._loop: DeadlineLoop | None = None
        self._lock = threading.Lock()
        self._last_command_s: float | None = None
        self._vented_at_s: float | None = None

    # -- wiring ------------------------------------------------------------------------
    def add_listener(self, listener: SampleListener) -> None:
        """Call ``listener`` with every sample (on the rig's thread; keep it short)."""
        with self._lock:
            self._listeners.append(listener)

    def remove_listener(self, listener: SampleListener) -> None:
        """Stop calling ``listener`` (no error if it was not added)."""
        with self._lock:
            if listener in self._listeners:
                self._listeners.remove(listener)

    def attach(self, emulator: Emulator) -> Emulator:
        """Have ``emulator`` started and stopped with the rig (started now if running)."""
        self._emulators.append(emulator)
        if self.running:
            emulator.start()
        return emulator

    # -- running -----------------------------------------------------------------------
    def start(self) -> None:
        """Compile the plant, start stepping it, then start the attached emulators."""
        self.hw.plant.warm_up()
        self.hw.reset_ticks()
        self._loop = DeadlineLoop(
            self.sample_rate_hz, self._tick, name="emulated-rig", rt_priority=self.rt_priority
        )
        self._loop.start()
        for emulator in self._emulators:
            emulator.start()
        if self.rt_priority:
            # The serving threads too (below the plant), or a reply waits behind the host.
            refused = set_process_realtime(self.rt_priority)
            self.realtime = refused or f"SCHED_FIFO {self.rt_priority}"
        else:
            self.realtime = "off (rt_priority 0)"

    def stop(self) -> None:
        """Stop the emulators, then the plant (idempotent)."""
        for emulator in self._emulators:
            emulator.stop()
        loop, self._loop = self._loop, None
        if loop is not None:
            loop.stop()

    @property
    def running(self) -> bool:
        """Whether the plant is being stepped."""
        return self._loop is not None and self._loop.running

    def __enter__(self) -> EmulatedRig:
        self.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()

    def _tick(self, k: int, deadline_s: float) -> None:
        # The devices sample on their own clocks whether or not this thread ran on time (on a
        # busy host it misses deadlines: 15 % with the whole emulated graph on 2 cores). After
        # an overrun, step through every missed sample, so the laser bridge streams the backlog
        # with consecutive counters as a bridge with a FIFO does, rather than a plant that
        # skips time the sensors never saw.
        for sample_time_s, sample in self.hw.step_through(k, deadline_s, 1.0 / self.sample_rate_hz):
            with self._lock:
                self._latest = sample
                listeners = tuple(self._listeners)
            for listener in listeners:
                listener(sample, sample_time_s)

    # -- what the emulators use --------------------------------------------------------
    def command(self, gauge_pa: float) -> bool:
        """Apply a valve set-point, gauge [Pa] (clamped; refused if not finite)."""
        now_s = time.monotonic()
        with self._lock:
            was_pa = self.hw.command_pa
            ok = self.hw.command(gauge_pa, now_s)
            if ok:
                self._last_command_s = now_s
                if was_pa > 0.0 and self.hw.command_pa <= 0.0:
                    self._vented_at_s = now_s
        return ok

    def state(self) -> dict[str, Any]:
        """The plant's truth now, as plain values (for the CLI's ``query``).

        Keys: ``t_s`` (monotonic now), ``command_pa`` (valve set-point in force),
        ``muscle_pa`` (pressure in the muscle, noise-free), ``measured_pa`` (what the
        transmitter reads), ``angle_deg`` (true bend), ``distance_m`` (laser),
        ``last_command_s`` (when the latest set-point was applied) and ``vented_at_s``
        (when the set-point last dropped from above 0 to 0), monotonic [s] or None;
        ``plant_steps`` (samples taken since start) and ``steps_caught_up`` (of those, taken
        late because the host was busy, then streamed as a backlog).
        """
        sample = self.latest
        with self._lock:
            last_s, vented_s = self._last_command_s, self._vented_at_s
        loop = self._loop
        stats = loop.stats() if loop is not None else None
        return {
            "plant_steps": self.hw.ticks_done,
            "steps_caught_up": None if stats is None else stats.missed,
            "t_s": time.monotonic(),
            "command_pa": self.hw.command_pa,
            "muscle_pa": None if sample is None else sample.muscle_pressure_pa,
            "measured_pa": self.measured_pressure_pa,
            "angle_deg": None if sample is None else math.degrees(sample.true_angle_rad),
            "distance_m": None if sample is None else sample.distance_m,
            "last_command_s": last_s,
            "vented_at_s": vented_s,
        }

    @property
    def latest(self) -> PlantSample | None:
        """The newest sample; None before the first step."""
        with self._lock:
            return self._latest

    @property
    def measured_pressure_pa(self) -> float:
        """What the transmitter reads now, gauge [Pa] (0 before the first step: vented)."""
        sample = self.latest
        return 0.0 if sample is None else sample.pressure_measured_pa

    @property
    def laser_voltage_v(self) -> float:
        """What the laser outputs now (inverse of eq. 3.1 on the sensed distance) [V]."""
        sample = self.latest
        distance_m = self.config.rig["straight_distance_m"] if sample is None else sample.distance_m
        return float(self.geometry.distance_to_voltage_v(distance_m))


# -- command line ------------------------------------------------------------------------
def _parse_plant_params(items: Sequence[str], seed: int) -> PlantConfig:
    values: dict[str, float | bool | str] = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep or not name:
            raise ParameterError(f"--plant-param wants name=value, got {item!r}")
        lowered = text.strip().lower()
        if lowered in ("true", "false"):
            values[name.strip()] = lowered == "true"
            continue
        try:
            values[name.strip()] = float(text)
        except ValueError:
            raise ParameterError(
                f"--plant-param {name}: {text!r} is not a number or true/false"
            ) from None
    return PlantConfig.from_flat(values, seed=seed)


def _build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m catheter_driver.emulators.rig",
        description="Emulated rig: plant + device emulators on ptys / CAN. Prints one JSON "
        "line {backend: factory params} and runs until SIGINT/SIGTERM.",
    )
    p.add_argument("--keller-pty", action="store_true", help="Keller transmitter on a pty")
    p.add_argument("--keller-address", type=int, default=1, help="its address (1..249)")
    p.add_argument("--keller-reference", default="gauge", choices=("gauge", "absolute"))
    p.add_argument("--dac-pty", action="store_true", help="DAC bridge valve on a pty")
    p.add_argument("--adc-pty", action="store_true", help="laser ADC bridge on a pty")
    p.add_argument("--canopen", action="store_true", help="CANopen AO valve on the CAN bus")
    p.add_argument("--canopen-node-id", type=int, default=1)
    p.add_argument("--adc-can", action="store_true", help="laser ADC bridge on the CAN bus")
    p.add_argument("--adc-can-id", type=lambda s: int(s, 0), default=0x300)
    p.add_argument(
        "--can-interface",
        default="socketcan",
        help="python-can interface (virtual works only within one process; use vcan across)",
    )
    p.add_argument("--can-channel", default="vcan0")
    p.add_argument(
        "--failsafe-timeout-s",
        type=float,
        default=0.2,
        help="the valve interfaces (DAC bridge, CANopen AO) vent after this long without a "
        "set-point [s]",
    )
    p.add_argument(
        "--link-dir",
        type=Path,
        default=None,
        help="where the stable symlinks to the ptys go (default: a new temporary directory, "
        "removed at exit)",
    )
    p.add_argument("--seed", type=int, default=0, help="plant noise seed")
    p.add_argument(
        "--rt-priority",
        type=int,
        default=DEFAULT_RT_PRIORITY,
        help="SCHED_FIFO priority of the plant loop (its device threads 30 below; 0: off). "
        "The devices it stands in for have their own processors; at normal priority the "
        "graph it serves starves it",
    )
    p.add_argument(
        "--plant-param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="plant setting as PlantConfig.from_flat takes it: a rig parameter "
        "(valve_time_constant_s=0.01), <effect>.enabled=false or <effect>.<param>=value",
    )
    return p


class _PtyDevice:
    """One pty-backed emulator of the CLI, reachable at a stable symlink."""

    def __init__(self, emulator: Emulator, endpoint: PtyEndpoint, link: Path) -> None:
        self.emulator = emulator
        self.endpoint = endpoint
        self.link = link
        self.plugged = True
        self._point_link()

    def _point_link(self) -> None:
        # Atomic: a driver opening the path sees the old target or the new one, never none.
        tmp = self.link.with_name(f".{self.link.name}.tmp")
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        tmp.symlink_to(self.endpoint.slave_path)
        tmp.replace(self.link)

    def unplug(self) -> None:
        """Close the pty (the driver's port dies) and remove the symlink, as udev would.

        The emulator keeps running, as a device keeps its own power: a valve interface's
        fail-safe still vents.
        """
        self.endpoint.close()
        with contextlib.suppress(FileNotFoundError):
            self.link.unlink()
        self.plugged = False

    def replug(self) -> None:
        """A new pty (a new /dev/pts/N); the symlink points at it."""
        self.endpoint.open()
        self._point_link()
        self.plugged = True

    def state(self) -> dict[str, Any]:
        return {
            "port": str(self.link),
            "pty": self.endpoint.slave_path if self.plugged else None,
            "plugged": self.plugged,
        }


class _Control:
    """The stdin command channel of the CLI (see the module docstring)."""

    def __init__(
        self, rig: EmulatedRig, emulators: dict[str, Emulator], ptys: dict[str, _PtyDevice]
    ) -> None:
        self.rig = rig
        self.emulators = emulators
        self.ptys = ptys
        self._out_lock = threading.Lock()

    def serve(self, stdin: TextIO, stdout: TextIO) -> None:
        """Answer each command line until stdin closes."""
        for line in stdin:
            if not line.strip():
                continue
            reply = self.handle(line)
            with self._out_lock:
                stdout.write(json.dumps(reply) + "\n")
                stdout.flush()

    def handle(self, line: str) -> dict[str, Any]:
        """One command line to its reply."""
        try:
            command = json.loads(line)
        except ValueError as exc:
            return {"ack": line.strip(), "ok": False, "error": f"not JSON: {exc}"}
        try:
            if not isinstance(command, dict):
                raise ParameterError("a command is a JSON object")
            extra = self._run(command)
        except (ParameterError, KeyError, OSError, TypeError, ValueError) as exc:
            return {"ack": command, "ok": False, "error": str(exc)}
        return {"ack": command, "ok": True, "t_s": time.monotonic(), **extra}

    def _run(self, command: dict[str, Any]) -> dict[str, Any]:
        if "fault" in command:
            emulator = self._emulator(command.get("device"))
            emulator.inject(command["fault"], command.get("count"))
            return {}
        if "unplug" in command:
            device = self._pty(command["unplug"])
            device.unplug()
            return device.state()
        if "replug" in command:
            device = self._pty(command["replug"])
            if device.plugged:
                raise ParameterError(f"{command['replug']} is plugged in")
            device.replug()
            return device.state()
        if command.get("query") == "state":
            return {"state": self.state()}
        raise ParameterError(
            'unknown command; valid: {fault, device[, count]}, {unplug}, {replug}, {query: "state"}'
        )

    def _emulator(self, name: object) -> Emulator:
        if name not in self.emulators:
            raise ParameterError(f"no device {name!r}; this rig has {', '.join(self.emulators)}")
        return self.emulators[str(name)]

    def _pty(self, name: object) -> _PtyDevice:
        if name not in self.ptys:
            raise ParameterError(
                f"{name!r} is not a pty device of this rig; unpluggable: {', '.join(self.ptys)}"
            )
        return self.ptys[str(name)]

    def state(self) -> dict[str, Any]:
        """The rig's truth plus each device's fault, plug and fail-safe state."""
        devices: dict[str, Any] = {}
        for name, emulator in self.emulators.items():
            entry: dict[str, Any] = {"fault": emulator.fault, "running": emulator.running}
            if name in self.ptys:
                entry.update(self.ptys[name].state())
            failsafe = getattr(emulator, "failsafe", None)
            if failsafe is not None:
                entry["failsafe"] = failsafe.state()
            devices[name] = entry
        return {**self.rig.state(), "devices": devices}


def main(argv: Sequence[str] | None = None) -> int:
    """Run the emulated rig until SIGINT/SIGTERM; see the module docstring for the output."""
    from catheter_driver.emulators.canopen_ao import CanopenAoEmulator
    from catheter_driver.emulators.dac_bridge import DacBridgeEmulator
    from catheter_driver.emulators.keller import KellerEmulator
    from catheter_driver.emulators.laser_adc import LaserAdcCanEmulator, LaserAdcSerialEmulator
    from catheter_driver.emulators.pty_endpoint import PtyEndpoint
    from catheter_driver.transports.can_transport import CanTransport

    args = _build_parser().parse_args(argv)
    try:
        config = _parse_plant_params(args.plant_param, args.seed)
        if not args.failsafe_timeout_s > 0.0:
            raise ParameterError(f"--failsafe-timeout-s must be > 0, got {args.failsafe_timeout_s}")
    except ParameterError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.rt_priority < 0 or args.rt_priority > 99:
        print(f"error: --rt-priority must be 0..99, got {args.rt_priority}", file=sys.stderr)
        return 2
    rig = EmulatedRig(config, rt_priority=args.rt_priority)
    own_dir = args.link_dir is None
    link_dir = Path(tempfile.mkdtemp(prefix="emulated-rig-")) if own_dir else args.link_dir
    link_dir.mkdir(parents=True, exist_ok=True)
    ports: dict[str, dict[str, Any]] = {}
    emulators: dict[str, Emulator] = {}
    ptys: dict[str, _PtyDevice] = {}
    can_params = {"interface": args.can_interface, "channel": args.can_channel}
    failsafe_s = args.failsafe_timeout_s

    def add_pty(backend: str, make: Callable[[PtyEndpoint], Emulator]) -> dict[str, Any]:
        endpoint = PtyEndpoint()
        emulator = rig.attach(make(endpoint))
        emulators[backend] = emulator
        ptys[backend] = _PtyDevice(emulator, endpoint, link_dir / backend)
        return {"port": str(ptys[backend].link)}

    try:
        if args.keller_pty:
            where = add_pty(
                "keller_serial",
                lambda ep: KellerEmulator(
                    rig, ep, address=args.keller_address, reference=args.keller_reference
                ),
            )
            ports["keller_serial"] = {
                **where,
                "address": args.keller_address,
                "reference": args.keller_reference,
            }
        if args.dac_pty:
            ports["dac_serial"] = add_pty(
                "dac_serial",
                lambda ep: DacBridgeEmulator(rig, ep, failsafe_timeout_s=failsafe_s),
            )
        if args.adc_pty:
            ports["adc_serial"] = add_pty("adc_serial", lambda ep: LaserAdcSerialEmulator(rig, ep))
        if args.canopen:
            bus = CanTransport(**can_params)
            emulators["canopen"] = rig.attach(
                CanopenAoEmulator(
                    rig, bus, node_id=args.canopen_node_id, failsafe_timeout_s=failsafe_s
                )
            )
            ports["canopen"] = {**can_params, "node_id": args.canopen_node_id}
        if args.adc_can:
            bus = CanTransport(**can_params)
            emulators["adc_can"] = rig.attach(
                LaserAdcCanEmulator(rig, bus, arbitration_id=args.adc_can_id)
            )
            ports["adc_can"] = {**can_params, "arbitration_id": args.adc_can_id}
        return _run(rig, ports, _Control(rig, emulators, ptys))
    finally:
        for device in ptys.values():
            with contextlib.suppress(OSError):
                device.link.unlink()
        if own_dir:
            shutil.rmtree(link_dir, ignore_errors=True)


def _run(rig: EmulatedRig, ports: dict[str, dict[str, Any]], control: _Control) -> int:
    done = threading.Event()

    def _on_signal(signum: int, _frame: object) -> None:
        done.set()

    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)
    try:
        rig.start()
    except Exception as exc:  # report any start failure by name, then exit non-zero
        print(f"error: cannot start the emulated rig: {exc}", file=sys.stderr)
        rig.stop()
        return 1
    if rig.rt_priority and not rig.realtime.startswith("SCHED_FIFO"):
        print(
            f"warning: real-time scheduling {rig.realtime}; the rig may fall behind "
            "on a busy host (its samples are then streamed late, never dropped)",
            file=sys.stderr,
        )
    print(json.dumps(ports), flush=True)
    # Commands on stdin; at EOF (no controller, or stdin is /dev/null) the rig just runs on.
    threading.Thread(
        target=control.serve, args=(sys.stdin, sys.stdout), name="rig-control", daemon=True
    ).start()
    try:
        while not done.wait(0.5):
            if not rig.running:
                print("error: the rig's loop stopped", file=sys.stderr)
                return 1
    finally:
        rig.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
