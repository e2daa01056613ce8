"""Pure planning on grid maps: paths (``planner``), the body's clearance
(``clearance``) and exploration targets (``frontier``)."""
