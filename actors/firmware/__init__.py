"""The rovers' firmware as actors: the seed's threads, ISRs and queues.

Layering inside the package (each module imports only those above it)::

    commands, devices                 the internal command codes; the ISR boundary
    odometry                          poses and dead reckoning (pure)
    occupancy, planner, frontier,     pure algorithms on grids
    clearance
    isr                               the five ISRs (Int A-E) posting Messages
    motor, lidar, mapping, ir, wifly  the driver actors (wifly also uses server.protocol)
    nav_*                             navigation actors (mapping, hiding, seeking)

The package never imports ``world``, and of ``server`` only ``server.protocol``
(tests/test_layers.py). The supervision trees live in ``supervisors.rover``.
"""

from actors.firmware.commands import Cmd, name_of
from actors.firmware.drivers.ir import IrSensor
from actors.firmware.drivers.isr import (
    IrAdcIsr,
    IrTimerIsr,
    LidarUartIsr,
    MotorCounterIsr,
    WiflyUartIsr,
)
from actors.firmware.drivers.lidar import LidarControl, Scan
from actors.firmware.drivers.motor import MotorControl, MotorTuning, PoseMemory
from actors.firmware.drivers.wifly import LinkMemory, Wifly
from actors.firmware.hardware import HardwareSpec, Interrupt, RoverHardware
from actors.firmware.localisation.odometry import Pose
from actors.firmware.mapping.map_management import MapManagement
from actors.firmware.mapping.occupancy import GridMap, OccupancyGrid

__all__ = [
    "Cmd", "GridMap", "HardwareSpec", "Interrupt", "IrAdcIsr", "IrSensor", "IrTimerIsr",
    "LidarControl", "LidarUartIsr", "LinkMemory", "MapManagement", "MotorControl",
    "MotorCounterIsr", "MotorTuning", "OccupancyGrid", "Pose", "PoseMemory", "RoverHardware",
    "Scan", "Wifly", "WiflyUartIsr", "name_of",
]
