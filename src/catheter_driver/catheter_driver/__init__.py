"""Hardware side of the PAM catheter: the simulated hardware node (and, later, real drivers)."""

__version__ = "0.1.0"
