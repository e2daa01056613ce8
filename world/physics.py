"""Rigid-body physics of the rovers in the room (pymunk).

Each rover is a dynamic box driven like pymunk's tank example: a kinematic
*control body* carries the wanted velocity and turn rate, and a `PivotJoint`
(linear) plus a `GearJoint` (angular), each with a limited force, drag the
rover towards it. Contacts with walls win over those limited forces, so a
rover pushing a wall stops; setting the rover's velocity directly instead lets
Chipmunk move it through walls (``measured-facts.md``).

Units: cm, s, kg (mass is nominal). Frame: the room's (see `world.geometry`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import pymunk

try:  # Chipmunk's C functions, which pymunk's own properties and Space.step call
    from pymunk._chipmunk_cffi import lib as _chipmunk
except ImportError:  # a pymunk laid out otherwise: its public API alone
    _chipmunk = None

from world.geometry import Pose, boundary_segments, room_segments
from world.params import DeviceParams


def _angle(body: pymunk.Body) -> float:
    """A body's angle [rad]: what its ``angle`` property reads, from Chipmunk directly
    where pymunk's C functions are at hand."""
    return body.angle if _chipmunk is None else _chipmunk.cpBodyGetAngle(body._body)


#: physics substep [s]; 10 ms keeps a 30 cm/s rover moving 0.3 cm per step
DEFAULT_SUBSTEP_S = 0.01
ROVER_MASS = 1.0
#: how hard the control joints may pull [mass*cm/s^2]; enough to reach full speed in ~50 ms
PIVOT_MAX_FORCE = 1500.0
GEAR_MAX_FORCE = 30000.0
WALL_RADIUS = 2.0


@dataclass(slots=True)
class RoverBody:
    """A rover's pymunk objects."""

    body: pymunk.Body
    control: pymunk.Body
    shape: pymunk.Poly
    commanded: tuple[float, float, float] | None = None
    """Speed [cm/s], turn rate [rad/s] and body heading [rad] last given to ``control``."""


class Physics:
    """The pymunk space of one room and its three rovers."""

    def __init__(self, room_size: tuple[float, float], obstacles: tuple, starts: dict[str, Pose],
                 params: DeviceParams, substep_s: float = DEFAULT_SUBSTEP_S) -> None:
        self.params = params
        self.substep_s = substep_s
        self.space = pymunk.Space()
        self.space.iterations = 10
        static = self.space.static_body
        w, h = room_size
        r = WALL_RADIUS
        # walls offset outwards by their radius so their inner face is the room's edge
        walls = [((-r, -r), (w + r, -r)), ((w + r, -r), (w + r, h + r)),
                 ((w + r, h + r), (-r, h + r)), ((-r, h + r), (-r, -r))]
        shapes = [pymunk.Segment(static, a, b, r) for a, b in walls]
        for x0, y0, x1, y1 in boundary_segments(list(obstacles)):
            shapes.append(pymunk.Segment(static, (x0, y0), (x1, y1), 0.1))
        for s in shapes:
            s.friction = 0.3
        self.space.add(*shapes)
        self.rovers: dict[str, RoverBody] = {}
        for role, pose in starts.items():
            self.rovers[role] = self._add_rover(pose)
        self._room = room_segments(w, h)

    def _add_rover(self, pose: Pose) -> RoverBody:
        p = self.params
        moment = pymunk.moment_for_box(ROVER_MASS, (p.length_cm, p.width_cm))
        body = pymunk.Body(ROVER_MASS, moment)
        body.position = (pose.x, pose.y)
        body.angle = math.radians(pose.heading_deg)
        shape = pymunk.Poly.create_box(body, (p.length_cm, p.width_cm))
        shape.friction = 0.3
        control = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        control.position = body.position
        control.angle = body.angle
        pivot = pymunk.PivotJoint(control, body, (0, 0), (0, 0))
        pivot.max_bias = 0.0  # no positional correction: only velocities are matched
        pivot.max_force = PIVOT_MAX_FORCE
        gear = pymunk.GearJoint(control, body, 0.0, 1.0)
        gear.error_bias = 0.0
        gear.max_bias = 0.0
        gear.max_force = GEAR_MAX_FORCE
        self.space.add(body, shape, control, pivot, gear)
        return RoverBody(body, control, shape)

    def set_tread_speeds(self, role: str, left_cm_s: float, right_cm_s: float) -> None:
        """Command the control body from the two tread speeds (differential drive) [cm/s].

        Both joints are anchored at the bodies' centres with no positional bias, so
        only the control body's velocities matter, not where it is.
        """
        rb = self.rovers[role]
        v = 0.5 * (left_cm_s + right_cm_s)
        omega = (right_cm_s - left_cm_s) / self.params.track_width_cm
        a = _angle(rb.body)
        if rb.commanded == (v, omega, a):
            return  # the control body already carries this (a rover at rest, mostly)
        rb.commanded = (v, omega, a)
        c = rb.control
        velocity = (v * math.cos(a), v * math.sin(a))
        if _chipmunk is None:
            c.velocity = velocity
            c.angular_velocity = omega
        else:  # what pymunk's setters call, without their attribute machinery
            _chipmunk.cpBodySetVelocity(c._body, velocity)
            _chipmunk.cpBodySetAngularVelocity(c._body, omega)

    def step(self, dt: float) -> None:
        """Advance the space by ``dt`` [s] in whole substeps.

        A substep is Chipmunk's own ``cpSpaceStep`` whenever pymunk's `Space.step` would
        do nothing around it (no body to check, nothing added or removed later, no
        post-step callback, not threaded: the rooms add every body before the first
        step and install no collision handler); that wrapper costs as much again as
        the step of three rovers in a room. Else, or where pymunk is laid out
        otherwise, `Space.step` itself.
        """
        n = max(1, round(dt / self.substep_s))
        h = dt / n
        space = self.space
        direct = self._direct_step()
        for _ in range(n):
            if direct is not None:
                direct(space._space, h)
            else:
                space.step(h)

    def _direct_step(self):  # noqa: ANN202 (a cffi function)
        """Chipmunk's ``cpSpaceStep`` when pymunk's wrapper has nothing else to do."""
        space = self.space
        try:
            idle = not (space._bodies_to_check or space._add_later or space._remove_later
                        or space._post_step_callbacks or space._removed_shapes
                        or space.threaded or space._locked)
        except AttributeError:
            return None
        return _chipmunk.cpSpaceStep if idle and _chipmunk is not None else None

    def state(self, role: str) -> tuple[float, float, float]:
        """x, y [cm] and heading [rad] (unwrapped) of a rover's body: what its
        ``position`` and ``angle`` read, from Chipmunk directly (no `Vec2d` made)."""
        b = self.rovers[role].body
        if _chipmunk is None:
            x, y = b.position
            return x, y, b.angle
        v = _chipmunk.cpBodyGetPosition(b._body)
        return v.x, v.y, _angle(b)

    def pose(self, role: str) -> Pose:
        """Ground-truth pose with the heading in [0, 360) [deg]."""
        x, y, a = self.state(role)
        return Pose(x, y, math.degrees(a) % 360.0)
