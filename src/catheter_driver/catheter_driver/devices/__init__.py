"""Device classes (driver side) for the rig's transmitter, valve and laser ADC."""
