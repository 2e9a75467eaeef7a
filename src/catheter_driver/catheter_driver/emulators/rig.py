"""The emulated rig as a program: the simulated plant behind emulated devices, in a process.

The rig itself (:class:`~catheter_driver.emulators.rig_core.EmulatedRig`), the device
emulators, their ptys and the command channel (:mod:`~catheter_driver.emulators.control`)
each have their own module; this one parses the arguments, builds and wires them, and runs
them until told to stop. Run it for integration tests (bringup starts it the same way)::

    python -m catheter_driver.emulators.rig --keller-pty --dac-pty --adc-pty
    python -m catheter_driver.emulators.rig --keller-pty --dac-pty --adc-pty \
        --plant my_lab.rod:make_plant     # a plant of your own (docs/simulated_rig.md)

A plant that cannot be loaded or breaks its contract at rest is refused before anything
starts (exit 2, the reason on stderr). One that breaks it while running (raises, returns a
non-finite value, cannot keep its rate) is stopped and the valve vented; the program then
says why on stderr and exits 1, closing its devices, so the drivers see them go.

It prints one JSON line (flushed) mapping each emulated device's backend name to the
parameters that reach it, e.g.
``{"keller_serial": {"port": "/tmp/emulated-rig-x/keller_serial", "address": 1}}``,
ready for ``devices.factory`` (``make_transmitter("keller_serial", **line["keller_serial"])``),
then runs until SIGINT or SIGTERM. A pty device's ``port`` is a stable symlink to its
``/dev/pts/N`` (as a udev rule gives a real adapter), so a driver finds a replugged device
at the same path.

Faults are injected at run time by JSON commands on stdin, one per line
(:class:`~catheter_driver.emulators.control.RigControl`); each is answered by one JSON line
on stdout, ``{"ack": <command>, "ok": true, "t_s": <monotonic>, ...}``
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
import shutil
import signal
import sys
import tempfile
import threading
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from catheter_driver.emulators.base import Emulator
from catheter_driver.emulators.canopen_ao import CanopenAoEmulator
from catheter_driver.emulators.control import RigControl
from catheter_driver.emulators.dac_bridge import DacBridgeEmulator
from catheter_driver.emulators.keller import KellerEmulator
from catheter_driver.emulators.laser_adc import LaserAdcCanEmulator, LaserAdcSerialEmulator
from catheter_driver.emulators.pty_endpoint import PtyDevice, PtyEndpoint
from catheter_driver.emulators.rig_core import EmulatedRig
from catheter_driver.transports.can_transport import CanTransport
from catheter_models.errors import ParameterError
from catheter_models.plant import CheckedPlant, PlantConfig, PlantError, make_plant
from catheter_ros.rt_loop import DEFAULT_RT_PRIORITY


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
        "--plant",
        default="",
        metavar="MODULE:FACTORY",
        help="a plant of your own behind the devices: module:factory or path/to/file.py:factory "
        "(default: the shipped simulator; docs/simulated_rig.md, 'Your own plant')",
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


def main(argv: Sequence[str] | None = None) -> int:
    """Run the emulated rig until SIGINT/SIGTERM; see the module docstring for the output."""
    args = _build_parser().parse_args(argv)
    if args.rt_priority < 0 or args.rt_priority > 99:
        print(f"error: --rt-priority must be 0..99, got {args.rt_priority}", file=sys.stderr)
        return 2
    try:
        config = _parse_plant_params(args.plant_param, args.seed)
        if not args.failsafe_timeout_s > 0.0:
            raise ParameterError(f"--failsafe-timeout-s must be > 0, got {args.failsafe_timeout_s}")
        plant: CheckedPlant = make_plant(args.plant, config)
    except (ParameterError, PlantError) as exc:
        # --plant-param and --seed set the shipped plant; make_plant names any a plant of
        # your own would ignore (as "rig.<name>", "effects.<name>...", "seed").
        print(f"error: {exc}", file=sys.stderr)
        return 2
    rig = EmulatedRig(config, plant=plant, rt_priority=args.rt_priority)
    own_dir = args.link_dir is None
    link_dir = Path(tempfile.mkdtemp(prefix="emulated-rig-")) if own_dir else args.link_dir
    link_dir.mkdir(parents=True, exist_ok=True)
    ports: dict[str, dict[str, Any]] = {}
    emulators: dict[str, Emulator] = {}
    ptys: dict[str, PtyDevice] = {}
    can_params = {"interface": args.can_interface, "channel": args.can_channel}
    failsafe_s = args.failsafe_timeout_s

    def add_pty(backend: str, make: Callable[[PtyEndpoint], Emulator]) -> dict[str, Any]:
        endpoint = PtyEndpoint()
        emulator = rig.attach(make(endpoint))
        emulators[backend] = emulator
        ptys[backend] = PtyDevice(endpoint, link_dir / backend)
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
        return _run(rig, ports, RigControl(rig, emulators, ptys))
    finally:
        for device in ptys.values():
            with contextlib.suppress(OSError):
                device.link.unlink()
        if own_dir:
            shutil.rmtree(link_dir, ignore_errors=True)


def _run(rig: EmulatedRig, ports: dict[str, dict[str, Any]], control: RigControl) -> int:
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
            if rig.check_plant():
                print(
                    f"error: the plant was stopped and the valve vented: {rig.fault}",
                    file=sys.stderr,
                    flush=True,
                )
                return 1
            if not rig.running:
                print("error: the rig's loop stopped", file=sys.stderr)
                return 1
    finally:
        rig.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
