"""The errors of the device layer, below both the transports and the devices.

A transport's failure (:class:`~catheter_driver.transports.base.TransportError`: port gone,
bus down) is a :class:`DeviceError`, so a driver catches one exception whatever failed.
The base classes live here, in their own file, because transports raise them and devices
import transports: were they defined with the devices, the transports would import upwards.
Nothing here imports rclpy, pyserial or python-can.
"""

from __future__ import annotations

from catheter_models.errors import CatheterError


class DeviceError(CatheterError):
    """A device cannot be reached: port gone, bus down, or the device answers with an error."""


class DeviceTimeout(DeviceError):  # noqa: N818 (reads as a condition, like TimeoutError)
    """A reply did not come within the timeout."""
