"""Control side of the PAM catheter: compensator, recorder, excitation, follow_trajectory."""

__version__ = "0.1.0"
