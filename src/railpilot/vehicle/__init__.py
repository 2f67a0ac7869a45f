"""Train and line models."""

from railpilot.vehicle.line import Line
from railpilot.vehicle.train import ElectricBrakeCurve, Train

__all__ = ["ElectricBrakeCurve", "Line", "Train"]
