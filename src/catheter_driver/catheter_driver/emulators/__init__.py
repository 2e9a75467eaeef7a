"""Device emulators: the far end of each wire protocol, wrapping the simulated plant.

Each emulator is a full peer of the real device (as python-can's ``VirtualBus`` is of a real
bus): it speaks the same bytes and frames, so the real device classes and nodes run against
it unchanged. :class:`~catheter_driver.emulators.rig_core.EmulatedRig` owns the plant and
steps it in real time; the emulators read its sensors and feed it valve set-points. The
emulators import that core; the program that builds a whole rig
(``python -m catheter_driver.emulators.rig``) imports both; nothing imports back.
"""
