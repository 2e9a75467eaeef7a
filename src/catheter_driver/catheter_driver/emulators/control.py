"""The emulated rig program's command channel: faults, unplug/replug and state queries.

Commands arrive as JSON lines (on the program's stdin); each is answered by one JSON line,
``{"ack": <command>, "ok": true, "t_s": <monotonic>, ...}`` (``"ok": false, "error": ...``
if refused)::

    {"fault": "no_reply", "device": "keller_serial"}   # also bad_crc, garbage; "count": n
    {"fault": "none", "device": "keller_serial"}       # clear it
    {"unplug": "dac_serial"}    # close the pty (the driver's port dies), remove the symlink
    {"replug": "dac_serial"}    # a new pty; the symlink now points at it
    {"query": "state"}          # the plant's truth and each device's state, under "state"

It is its own file because it is neither the rig (:mod:`~catheter_driver.emulators.rig_core`)
nor the program's argument handling (:mod:`~catheter_driver.emulators.rig`): it only turns
command lines into calls on the rig, its emulators and their ptys.
"""

from __future__ import annotations

import json
import threading
import time
from typing import Any, TextIO

from catheter_driver.emulators.base import Emulator
from catheter_driver.emulators.pty_endpoint import PtyDevice
from catheter_driver.emulators.rig_core import EmulatedRig
from catheter_models.errors import ParameterError


class RigControl:
    """The rig program's command channel: one JSON command per line, one JSON reply each.

    Args:
        rig: the rig whose state ``query`` reports.
        emulators: the device emulators by backend name (``fault`` targets).
        ptys: the pty-backed ones by backend name (``unplug``/``replug`` targets).
    """

    def __init__(
        self, rig: EmulatedRig, emulators: dict[str, Emulator], ptys: dict[str, PtyDevice]
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

    def _pty(self, name: object) -> PtyDevice:
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
