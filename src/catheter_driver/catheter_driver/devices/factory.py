"""Devices chosen by a backend name from the node's parameters, imported only when chosen.

Each table maps a backend name to ``(module, class)``; the class's ``from_params`` takes the
backend's parameters as keyword arguments (plain values, as ROS parameters carry them).
An unknown backend or parameter is refused by name, so a typo never leaves a default in
force silently.

>>> valve = make_valve("canopen", channel="can0", node_id=3)  # doctest: +SKIP
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Mapping
from typing import Any, Final

from catheter_driver.devices.base import LaserAdc, PressureTransmitter, ValveSetpoint
from catheter_models.errors import ParameterError

TRANSMITTERS: Final[Mapping[str, tuple[str, str]]] = {
    "keller_serial": ("catheter_driver.devices.keller_transmitter", "KellerTransmitter"),
}
VALVES: Final[Mapping[str, tuple[str, str]]] = {
    "canopen": ("catheter_driver.devices.canopen_valve", "CanopenValve"),
    "dac_serial": ("catheter_driver.devices.dac_bridge_valve", "DacBridgeValve"),
}
LASER_ADCS: Final[Mapping[str, tuple[str, str]]] = {
    "adc_serial": ("catheter_driver.devices.serial_laser_adc", "SerialLaserAdc"),
    "adc_can": ("catheter_driver.devices.can_laser_adc", "CanLaserAdc"),
}


def backend_params(table: Mapping[str, tuple[str, str]], backend: str) -> dict[str, Any]:
    """The parameters a backend takes, with defaults (``inspect.Parameter.empty``: required).

    Imports the backend's module.

    Raises:
        ParameterError: unknown backend.
    """
    factory = _from_params(table, backend, "device")
    return {name: p.default for name, p in inspect.signature(factory).parameters.items()}


def _from_params(table: Mapping[str, tuple[str, str]], backend: str, kind: str) -> Any:
    if backend not in table:
        raise ParameterError(f"unknown {kind} backend {backend!r}; valid: {', '.join(table)}")
    module_name, class_name = table[backend]
    return getattr(importlib.import_module(module_name), class_name).from_params


def _make(
    table: Mapping[str, tuple[str, str]],
    kind: str,
    base: type,
    backend: str,
    params: Mapping[str, Any],
) -> Any:
    factory = _from_params(table, backend, kind)
    signature = inspect.signature(factory).parameters
    unknown = sorted(set(params) - set(signature))
    if unknown:
        raise ParameterError(
            f"{kind} backend {backend!r} has no parameter(s) {', '.join(unknown)}; "
            f"it takes: {', '.join(signature)}"
        )
    missing = [
        n for n, p in signature.items() if p.default is inspect.Parameter.empty and n not in params
    ]
    if missing:
        raise ParameterError(f"{kind} backend {backend!r} needs parameter(s) {', '.join(missing)}")
    device = factory(**params)
    if not isinstance(device, base):
        raise TypeError(f"{kind} backend {backend!r} built a {type(device).__name__}")
    return device


def make_transmitter(backend: str, **params: Any) -> PressureTransmitter:
    """A pressure transmitter by backend name (:data:`TRANSMITTERS`), not yet opened.

    Raises:
        ParameterError: unknown backend, unknown or missing parameter, or a value out of range.
    """
    device: PressureTransmitter = _make(
        TRANSMITTERS, "transmitter", PressureTransmitter, backend, params
    )
    return device


def make_valve(backend: str, **params: Any) -> ValveSetpoint:
    """A valve set-point device by backend name (:data:`VALVES`), not yet opened.

    Raises:
        ParameterError: unknown backend, unknown or missing parameter, or a value out of range.
    """
    device: ValveSetpoint = _make(VALVES, "valve", ValveSetpoint, backend, params)
    return device


def make_laser_adc(backend: str, **params: Any) -> LaserAdc:
    """A laser ADC by backend name (:data:`LASER_ADCS`), not yet opened.

    Raises:
        ParameterError: unknown backend, unknown or missing parameter, or a value out of range.
    """
    device: LaserAdc = _make(LASER_ADCS, "laser ADC", LaserAdc, backend, params)
    return device
