"""The emulated rig: the simulated plant stepped in real time, behind emulated devices.

:class:`EmulatedRig` owns a :class:`~catheter_driver.sim_hardware.SimHardware` and steps it
at the plant's sample rate (250 Hz) on a deadline loop. Device emulators read its sensors
and feed it valve set-points, each over its own wire protocol.

Run as a program, it is a whole rig in a separate process for integration tests::

    python -m catheter_driver.emulators.rig --keller-pty --dac-pty --adc-pty

It prints one JSON line (flushed) mapping each emulated device's backend name to the
parameters that reach it, e.g. ``{"keller_serial": {"port": "/dev/pts/5", "address": 1}}``,
ready for ``devices.factory`` (``make_transmitter("keller_serial", **line["keller_serial"])``),
then runs until SIGINT or SIGTERM.
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from types import TracebackType
from typing import TYPE_CHECKING, Any

from catheter_driver.rt_loop import DeadlineLoop
from catheter_driver.sim_hardware import SimHardware
from catheter_models.errors import ParameterError
from catheter_models.plant import PlantConfig, PlantSample

if TYPE_CHECKING:
    from catheter_driver.emulators.base import Emulator

SampleListener = Callable[[PlantSample, float], None]
"""Called on the rig's thread with each new sample and its deadline [monotonic s]."""


class EmulatedRig:
    """The simulated plant in real time, with the emulators attached to it.

    Args:
        config: plant configuration; the thesis rig by default.
        max_pressure_pa: highest set-point applied, gauge [Pa]; the valve's maximum by default.
        command_timeout_s: vent after this long without a set-point [s]. A real regulator
            holds its last set-point forever (the driver node owns the watchdog), hence inf.
    """

    def __init__(
        self,
        config: PlantConfig | None = None,
        *,
        max_pressure_pa: float | None = None,
        command_timeout_s: float = math.inf,
    ) -> None:
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
        self._loop = DeadlineLoop(self.sample_rate_hz, self._tick, name="emulated-rig")
        self._loop.start()
        for emulator in self._emulators:
            emulator.start()

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

    def _tick(self, _k: int, deadline_s: float) -> None:
        sample = self.hw.step(deadline_s)
        with self._lock:
            self._latest = sample
            listeners = tuple(self._listeners)
        for listener in listeners:
            listener(sample, deadline_s)

    # -- what the emulators use --------------------------------------------------------
    def command(self, gauge_pa: float) -> bool:
        """Apply a valve set-point, gauge [Pa] (clamped; refused if not finite)."""
        return self.hw.command(gauge_pa, time.monotonic())

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
    p.add_argument("--seed", type=int, default=0, help="plant noise seed")
    p.add_argument(
        "--plant-param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="plant setting as PlantConfig.from_flat takes it: a rig parameter "
        "(valve_time_constant_s=0.01), <effect>.enabled=false or <effect>.<param>=value",
    )
    return p


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
    except ParameterError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    rig = EmulatedRig(config)
    ports: dict[str, dict[str, Any]] = {}
    can_params = {"interface": args.can_interface, "channel": args.can_channel}
    if args.keller_pty:
        endpoint = PtyEndpoint()
        rig.attach(
            KellerEmulator(
                rig, endpoint, address=args.keller_address, reference=args.keller_reference
            )
        )
        ports["keller_serial"] = {
            "port": endpoint.slave_path,
            "address": args.keller_address,
            "reference": args.keller_reference,
        }
    if args.dac_pty:
        endpoint = PtyEndpoint()
        rig.attach(DacBridgeEmulator(rig, endpoint))
        ports["dac_serial"] = {"port": endpoint.slave_path}
    if args.adc_pty:
        endpoint = PtyEndpoint()
        rig.attach(LaserAdcSerialEmulator(rig, endpoint))
        ports["adc_serial"] = {"port": endpoint.slave_path}
    if args.canopen:
        bus = CanTransport(**can_params)
        rig.attach(CanopenAoEmulator(rig, bus, node_id=args.canopen_node_id))
        ports["canopen"] = {**can_params, "node_id": args.canopen_node_id}
    if args.adc_can:
        bus = CanTransport(**can_params)
        rig.attach(LaserAdcCanEmulator(rig, bus, arbitration_id=args.adc_can_id))
        ports["adc_can"] = {**can_params, "arbitration_id": args.adc_can_id}

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
    print(json.dumps(ports), flush=True)
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
