"""The mapper's tunables (`MappingOptions`): the physical quantities of exploration,
the completion test, homing and the hold for a faulty LIDAR."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["MappingOptions"]


@dataclass(frozen=True, slots=True)
class MappingOptions:
    """Physical quantities of exploration and of the completion test.

    The counts, bounds and shares of the algorithms (frontier choice, the futile-trip
    rule, the change test, the odometry holds) are constants beside them
    (`exploration`, `mapper`, `homing`, `sensor_watch`).
    """

    lidar_duty: float = 0.5
    """LIDAR rotation PWM for mapping (Command B) [1]: 5.5 rev/s with the calibrated
    motor."""
    view_range_cm: float = 250.0
    """The LIDAR's useful range for seeing into the unknown [cm]: exploration chooses
    poses that see the frontier from no farther (at 2.5 m one revolution's 1 deg
    samples are 4.4 cm apart, under a cell, so what a pose sees is mapped)."""
    reach_cm: float = 10.0
    """A viewpoint counts as reached this close [cm]."""
    stop_cm: float = 20.0
    """Stop this far before an obstacle ahead (centre to cell centre) [cm]."""
    stable_window_s: float = 10.0
    """The map must not have changed for this long [s], navigation not holding, for
    mapping to be complete."""
    budget_s: float = 900.0
    """Mapping time budget: upload what is known after this [s]."""
    home_budget_s: float = 180.0
    """Most time spent driving back to the start before uploading; 0 skips homing [s]."""
    home_reach_cm: float = 15.0
    """Home counts as reached this close to the start [cm]."""
    lidar_pause_s: float = 60.0
    """Hold still for a LIDAR fault at most this long, then drive on regardless for as
    long before holding again [s]."""
