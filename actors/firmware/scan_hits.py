"""What a usable LIDAR hit is: one notion for scan matching and the scan likelihood.

Scan matching (`mapping.scan_match`) and the scan likelihood
(`localisation.scan_likelihood`, `localisation.face_information`) read one
LIDAR, so they use the same hits: none nearer than ``MIN_RANGE_CM`` (too close
to tell direction well), none farther than ``MAX_RANGE_CM`` (the occupancy
model's longest return, `mapping.sensor_model.LogOddsModel.max_range_cm`), and
no verdict on fewer than ``MIN_POINTS`` of them, nor on a scan with under
``MIN_JUDGED`` of them on known ground. Units: [cm].
"""

from __future__ import annotations

__all__ = ["MIN_POINTS", "MIN_JUDGED", "MIN_RANGE_CM", "MAX_RANGE_CM"]

MIN_POINTS = 12
"""Fewer usable hits than this say nothing about a pose [hits]."""
MIN_JUDGED = 0.35
"""Share of the usable hits that must be on known ground for a scan to say anything about
a pose [1]: the scan likelihood judges a fit only when this share is off new ground
(`localisation.scan_likelihood.judge_fit`), and scan matching matches only when this
share lands on mapped obstacles at the guess or at the result, and a re-localisation's
winner only when this share of its hits does (`mapping.scan_match`): a
scan of a part of the room never seen is neither judged nor matched."""
MIN_RANGE_CM = 12.0
"""Nearer hits are not used: too close to tell direction well [cm]."""
MAX_RANGE_CM = 600.0
"""Farther hits are not used: too uncertain to mark or match [cm]."""
