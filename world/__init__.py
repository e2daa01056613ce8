"""The simulated world: room, rovers, devices, faults, scenarios, ground truth.

Layering inside the package (each module imports only those above it)::

    geometry, params, packets, raycast, faults   pure data and maths
    scenario -> generator, truth -> metrics      scenario files, ground truth, scores
    physics, drive, lidar, ir, wifly             pymunk bodies and device models
    hardware -> world                            the ISR boundary and the stepped World

The world never imports server or supervisors, and of the firmware only the
device contract ``actors.firmware.hardware`` (which it implements): firmware
reaches it only through `SimRoverHardware` (device commands and interrupts).
"""

from world.faults import ACTOR_FAULTS, DEVICE_FAULTS, ROLE_ACTORS, Fault, check_fault
from world.geometry import Pose
from world.hardware import SimRoverHardware
from world.metrics import accuracy, coverage, path_length, t90, t99, time_to_coverage
from world.params import ROLES, DeviceParams, rover_spec
from world.scenario import (
    Scenario,
    ScenarioError,
    ScheduledFault,
    builtin_scenarios,
    generate_scenario,
    load_scenario,
    parse_scenario,
)
from world.truth import TruthGrid, truth_raster
from world.wifly import WiflyLink
from world.world import DEFAULT_TICK_S, World, run_world

__all__ = [
    "ACTOR_FAULTS", "DEVICE_FAULTS", "DEFAULT_TICK_S", "ROLES", "ROLE_ACTORS", "DeviceParams",
    "Fault", "Pose", "Scenario", "ScenarioError", "ScheduledFault",
    "SimRoverHardware", "TruthGrid", "WiflyLink", "World", "accuracy", "builtin_scenarios",
    "check_fault", "coverage", "generate_scenario", "load_scenario", "parse_scenario",
    "path_length", "rover_spec", "run_world", "t90", "t99", "time_to_coverage", "truth_raster",
]
