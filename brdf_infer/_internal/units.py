"""Unit conversions: the public interface is in degrees, the trigonometry in radians."""

import math

DEG: float = math.pi / 180.0  # radians per degree
