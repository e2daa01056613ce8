"""What a usable LIDAR hit is: one notion for scan matching and the scan likelihood.

Scan matching (`mapping.scan_match`) and the scan likelihood
(`localisation.scan_likelihood`, `localisation.face_information`) read one
LIDAR, so they use the same hits: none nearer than ``MIN_RANGE_CM`` (too close
to tell direction well), none farther than ``MAX_RANGE_CM`` (the occupancy
model's longest return, `mapping.sensor_model.LogOddsModel.max_range_cm`), and
no verdict on fewer than ``MIN_POINTS`` of them. Units: [cm].
"""

from __future__ import annotations

__all__ = ["MIN_POINTS", "MIN_RANGE_CM", "MAX_RANGE_CM"]

MIN_POINTS = 12
"""Fewer usable hits than this say nothing about a pose [hits]."""
MIN_RANGE_CM = 12.0
"""Nearer hits are not used: too close to tell direction well [cm]."""
MAX_RANGE_CM = 600.0
"""Farther hits are not used: too uncertain to mark or match [cm]."""
