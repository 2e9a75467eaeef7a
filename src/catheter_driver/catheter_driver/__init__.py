"""Hardware side of the PAM catheter: device drivers, their emulators, the simulated rig node."""

__version__ = "0.1.0"
