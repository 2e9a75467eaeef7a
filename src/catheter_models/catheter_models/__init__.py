"""Science core of the PAM catheter stack.

Signals, metrics, the simulated plant, geometry and bag I/O. Nothing here imports rclpy:
the ROS nodes in ``catheter_driver`` and ``catheter_control`` are thin shells over these objects.
"""

__version__ = "0.1.0"
