"""Command codes of the rovers' internal messages: the firmware's ``enum``.

Every internal queue carries the seed's 96-bit message (`actors.Message`):
``command`` says what the message is, ``type`` how to read ``value``. The
codes are grouped by the queue that receives them, as a C header would be, so a
trace line can be decoded to a name (`name_of`).

Units on the wire between actors: distances in [mm] or [cm] as named, angles
in [0.1 deg] when packed into int16 pairs, [deg] as float32 otherwise.
"""

from __future__ import annotations

import enum

__all__ = ["Cmd", "name_of"]


class Cmd(enum.IntEnum):
    """Internal command / event codes, one namespace for all queues."""

    NOOP = 0x0001
    """Does nothing, on any queue; what a flood fault fills a queue with. Actors ignore it."""

    # -- Motor queue ------------------------------------------------------
    MOTOR_MOVE = 0x0100
    """Command A: move straight; value float32 [cm], negative backwards."""
    MOTOR_TURN = 0x0101
    """Command A: turn in place; value float32 [deg], positive counter-clockwise."""
    MOTOR_STOP = 0x0102
    """Command A: stop both treads now."""
    MOTOR_TICK = 0x0103
    """Int E from the motor counter ISR; value int32 = encoded tread and direction."""
    MOTOR_CONTROL = 0x0104
    """Motor control loop period elapsed (self-timer); value unused."""

    MOTOR_GET_POSE = 0x0105
    """Publish the current dead-reckoned pose (own frame) to the pose subscribers now:
    navigation (NAV_POSE_*) and, on the mapper, the LIDAR (LIDAR_POSE_*)."""

    # -- Navigation queue --------------------------------------------------
    NAV_POSE_XY = 0x0200
    """Dead-reckoned position in the rover's own frame; value int16 pair (x, y) [mm].

    Sent by Motor Control (the owner of dead reckoning) whenever the pose
    changed, always followed by NAV_POSE_HEADING."""
    NAV_POSE_HEADING = 0x0201
    """Dead-reckoned heading in the rover's own frame; value float32 [deg]."""
    NAV_MOTION_DONE = 0x0202
    """Motor finished the current Command A; value float32 distance [cm] or angle [deg] done."""
    NAV_MOTION_BLOCKED = 0x0203
    """Motor gave up: treads commanded but no encoder progress; value float32 done so far."""
    NAV_MAP_UPDATE = 0x0204
    """Map Management published a grid snapshot; value handle of a `GridMap`."""
    NAV_SCAN_COUNT = 0x0205
    """Map Management integrated scans; value uint32 total scan batches so far."""
    NAV_NET = 0x0206
    """A frame from the server; value handle of the decoded `Frame`."""
    NAV_MAP_DOWNLOAD = 0x0207
    """A whole map downloaded from the server; value handle of a `GridMap` (map frame)."""
    NAV_IR = 0x0208
    """IR decision; value int32 (1 hider in range, 0 not, 2 no decision: the sensor is pinned
    at an ADC rail), sent on change and every sample batch."""
    NAV_TIMER = 0x0209
    """Navigation's own periodic tick; value unused."""
    NAV_LINK = 0x020A
    """WiFly link state changed; value int32 (1 up, 0 down)."""
    NAV_MAP_LOST = 0x020B
    """Map Management restarted with an empty grid (value unused). Navigation answers
    MAP_ORIGIN_XY + MAP_ORIGIN_HEADING with the origin it holds (Map Management drops
    scans until they arrive), and may answer MAP_RESTORE with the last `GridMap` it
    received."""
    NAV_LIDAR_HEALTH = 0x020C
    """LIDAR Control's verdict on its sensor changed; value int32, a `lidar.LidarHealth`
    (0 healthy; otherwise the fault seen: scans are withheld until it is healthy again)."""
    NAV_TREAD_FAULT = 0x020D
    """Motor Control saw a tread that is driven but does not count (a stuck encoder, or a
    stalled tread), or counts short (a slipping encoder, or a weak motor), while the other
    one counts; value uint32: bit 0 the tread (0 left, 1 right), bit 1 set for "counts
    short" (so 0/1 silent, 2/3 short), bit 2 for both treads: 4 a turn blocked without
    one Int E (both silent; its NAV_MOTION_BLOCKED follows), 6 both count short. At
    most once of each per tread per Command A; the command goes on (navigation
    decides). See motor.py."""

    NAV_MAP_ORIGIN_XY = 0x020E
    """Map Management's map -> odometry transform (mapper: the correction its scan matching
    found; the odometry frame's origin in the map frame), translation; value int16 pair
    (x, y) [mm]. Always followed by NAV_MAP_ORIGIN_HEADING. Navigation keeps it as its
    ``origin`` (map pose = origin (+) Motor Control's pose), retained in `NavMemory`."""
    NAV_MAP_ORIGIN_HEADING = 0x020F
    """The origin's rotation; value float32 [deg]."""
    NAV_TREAD_DRIVEN = 0x0210
    """How far Motor Control's drive model says each tread went in a Command A that had a
    NAV_TREAD_FAULT, or a turn that ended blocked (its counts are not its travel); value int16 pair
    (left, right) [mm], signed as driven, including the coast to rest after the stop.
    Sent once, just before that command's NAV_MOTION_DONE / NAV_MOTION_BLOCKED."""

    # -- LIDAR queue -------------------------------------------------------
    LIDAR_SAMPLE = 0x0300
    """Data Packet A unpacked by the ISR; value int16 pair (angle [0.1 deg], distance [cm])."""
    LIDAR_START = 0x0301
    """Command B: start rotating; value float32 PWM duty in (0, 1]."""
    LIDAR_STOP = 0x0302
    """Command B: stop rotating."""
    LIDAR_RATE = 0x0303
    """Command B: set rotation PWM; value float32 duty."""
    LIDAR_POSE_XY = 0x0304
    """Current rover position; value int16 pair (x, y) [cm]."""
    LIDAR_POSE_HEADING = 0x0305
    """Current rover heading; value float32 [deg]."""
    LIDAR_SAMPLES = 0x0306
    """A whole interrupt's Data Packet A frames, decoded by the ISR (the DMA-buffer way);
    value handle of a `isr.LidarSamples` (angles [0.1 deg], distances [cm])."""

    # -- Map Management queue ----------------------------------------------
    MAP_SCAN = 0x0400
    """A batch of points; value handle of (pose, angles [deg], ranges [cm])."""
    MAP_GET = 0x0401
    """Ask for a full snapshot (after a restart of navigation); value unused."""
    MAP_RESTORE = 0x0402
    """Seed the grid after a restart: value handle of a `GridMap` (navigation's last copy).
    Cells the new grid has not observed yet take the snapshot's class."""
    MAP_ORIGIN_XY = 0x0403
    """Navigation's copy of the map -> odometry transform, its answer to NAV_MAP_LOST (a
    restarted Map Management takes its correction back from it), translation; value
    int16 pair (x, y) [mm]. Always followed by MAP_ORIGIN_HEADING."""
    MAP_ORIGIN_HEADING = 0x0404
    """The origin's rotation; value float32 [deg]."""
    MAP_TREAD_FAULT = 0x0405
    """From navigation, relaying Motor Control's NAV_TREAD_FAULT for the motion that just
    ended: value int16 pair (left, right) [mm], the travel Motor Control's model drove
    each reported tread beyond its count (signed; 0 for a tread not reported). Map
    Management widens its pose belief by it (`localisation.gaussian_pose`)."""

    # -- WiFly queue -------------------------------------------------------
    WIFLY_RX = 0x0500
    """Bytes received by the UART ISR; value handle of the bytes."""
    WIFLY_SEND = 0x0501
    """Send a frame to the server reliably; value handle of the frame dict."""
    WIFLY_SEND_UNRELIABLE = 0x0502
    """Send a frame without seq (telemetry); value handle of the frame dict."""
    WIFLY_TIMER = 0x0503
    """WiFly's own periodic tick (heartbeat, resend); value unused."""
    WIFLY_SEND_MAP = 0x0504
    """Upload a map in chunks, reliably; value handle of a `GridMap`."""
    WIFLY_LINK_OPEN = 0x0505
    """The module opened a new connection to the server (a WiFly's ``*OPEN*``): say
    hello at once; value unused."""

    # -- IR queue ----------------------------------------------------------
    IR_SAMPLE = 0x0600
    """ADC sample from the IR ADC ISR; value int32 0..4095."""
    IR_LEASE = 0x0601
    """Navigation's lease on IR sampling; value float32 [s] from now (0 stops at once)."""


def name_of(command: int) -> str:
    """Readable name of a command code, or its hex value when unknown."""
    try:
        return Cmd(command).name
    except ValueError:
        return f"0x{command:04x}"
