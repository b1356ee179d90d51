"""hasel: the ROS-free core of the HASEL soft-actuator toolkit.

Everything numerical lives here (plant model, sensors, filters, the dual-mode PID,
calibration, MCAP and CSV loading, identification, diagnosis), so that the same code
runs inside an rclpy node, in log replay and offline. This package never imports
rclpy. Units: stroke in mm, voltage in kV, time in float seconds (int nanoseconds only
at the ROS and MCAP boundary, converted in :mod:`hasel.timeconv`).
"""
from hasel.errors import BadInputError, HaselError

__all__ = ["HaselError", "BadInputError", "__version__"]
__version__ = "0.1.0"
