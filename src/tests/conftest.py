"""Fixtures of the core's unit tests (no ROS here)."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
