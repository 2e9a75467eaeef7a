"""Transports chosen by name, each imported only when chosen (python-can's backend table).

>>> t = make_transport("serial", url="/dev/ttyUSB0", baudrate=115200)  # doctest: +SKIP
"""

from __future__ import annotations

import importlib
from typing import Any, Final

from catheter_driver.transports.base import ByteTransport, FrameTransport, TransportError
from catheter_models.errors import ParameterError

TRANSPORTS: Final[dict[str, tuple[str, str]]] = {
    "serial": ("catheter_driver.transports.serial_transport", "SerialTransport"),
    "can": ("catheter_driver.transports.can_transport", "CanTransport"),
}
"""Transport name -> (module, class). The module is imported on first use."""


def make_transport(kind: str, **params: Any) -> ByteTransport | FrameTransport:
    """Build a transport by name (not yet opened).

    Args:
        kind: a key of :data:`TRANSPORTS`.
        **params: the transport class's keyword arguments.

    Raises:
        ParameterError: unknown name or parameters.
    """
    if kind not in TRANSPORTS:
        raise ParameterError(f"unknown transport {kind!r}; valid: {', '.join(sorted(TRANSPORTS))}")
    module_name, class_name = TRANSPORTS[kind]
    cls = getattr(importlib.import_module(module_name), class_name)
    try:
        transport: ByteTransport | FrameTransport = cls(**params)
    except TypeError as exc:
        raise ParameterError(f"transport {kind!r}: {exc}") from None
    return transport


__all__ = [
    "TRANSPORTS",
    "ByteTransport",
    "FrameTransport",
    "TransportError",
    "make_transport",
]
