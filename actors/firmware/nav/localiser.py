"""The hider's and seeker's pose belief: where the rover is, and how sure it is.

`Localiser` is a part of the hider's and seeker's navigation actor
(`route_nav.RouteNav`). It keeps one
`localisation.belief.PoseBelief` (a particle filter over the map-frame pose)
and makes it the source of the map -> odometry transform (the ``origin``) and
of the doubt every recovery behaviour reads (`drift_cm`: the belief's 95 %
radius).

What drives it
    * **Motion**: at every pose at rest, the own-frame motion since the last
      one, as Motor Control counted it, becomes each tread's counted travel
      (midpoint rule inverted: ``ds`` along the mean heading, ``dtheta`` over
      the track width) and moves the particles through the tread motion model
      (`motion_model.sample_motion`). A ``NAV_TREAD_FAULT`` received during the
      motion marks the tread(s) reported; their modelled travel is the other
      tread's count (one tread reported: both are driven alike in size) or the
      commanded motion's (both reported), so the doubt follows from the
      geometry, not from added degrees. On the server's map, a particle the
      motion carried into a face at a slant slides along it (`slide_model`):
      the encoders count only the part of a slide along the heading.
    * **Free space**: at every rest the particles whose body overlaps a wall of
      the server's map lose weight (`free_space_model`).
    * **Contact**: a straight move that ended blocked weighs the particles by
      the contact model (`contact_model`, the stalled side from the yaw while
      stalled), keeping every explanation (two clusters at a gap's mouth).
      The update is made only when the map's walls explain the stop better
      than something unmapped: the belief's expected touch likelihood must
      exceed the model's ``unmapped_weight`` (the Bayes factor of the two
      explanations is over one).

After every update the origin is set so that the map-frame pose is the
heaviest hypothesis's mean (`Spread.best`); Motor Control's dead reckoning is
left continuous. Randomness: one generator per navigation incarnation, seeded
from the rover's role (the firmware has no other random source), so a seed
gives the same game.

Restart: the belief (its particles, the dead-reckoning set beside it, the
own-frame pose they were last moved to) and the server's origin it started
from are kept in the retained `NavMemory` after every update (`BeliefMemory`).
A restarted navigation goes on from them: Motor Control's dead reckoning ran
on meanwhile, so the next pose at rest moves the belief by everything driven
since, and a retried destination's origin is still known for what it is.
Drawn afresh round the retained origin, the belief would lose its doubt (the
start's 1 cm), and the first ``origin`` frame after the restart would look like
a new placement and put the rover back on dead reckoning from its start.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from actors.firmware.drivers.tread_monitor import BOTH_MOVE_RATIO, TreadFault
from actors.firmware.localisation.belief import PoseBelief, Spread
from actors.firmware.localisation.contact import stalled_side
from actors.firmware.localisation.contact_model import (
    ContactOptions,
    contact_gap_cm,
    contact_log_likelihood,
)
from actors.firmware.localisation.dead_reckoning import DeadReckoning
from actors.firmware.localisation.distance_field import DistanceField
from actors.firmware.localisation.free_space_model import free_space_log_likelihood
from actors.firmware.localisation.motion_model import TreadMotion, TreadReport
from actors.firmware.localisation.odometry import tread_travel
from actors.firmware.localisation.slide_model import slide_along_faces
from actors.firmware.nav.route import Motion
from server.protocol.grid_map import GridMap
from server.protocol.pose import Pose, angle_diff_deg, compose, inverse

if TYPE_CHECKING:
    from actors.firmware.nav.route_nav import RouteNav

__all__ = ["Localiser", "BeliefMemory", "START_SIGMA_CM", "START_SIGMA_DEG",
           "RETRY_PRIOR_SHARE"]

START_SIGMA_CM = 1.0
"""Standard deviation of x and y of the belief at the server's ``origin`` [cm]: the
rover stands where the server placed it, to within its placement."""
START_SIGMA_DEG = 1.0
"""Standard deviation of the heading of the belief at the server's ``origin`` [deg]."""
RETRY_PRIOR_SHARE = 0.5
"""Weight of dead reckoning alone in the belief a retried destination starts from [1]:
the route before it was given up after its contacts, as likely misread as read right
(see `Localiser.on_server_origin`)."""


def _same_pose(a: Pose, b: Pose) -> bool:
    """``a`` and ``b`` are one pose, to the precision a frame carries (0.01 cm, deg)."""
    return math.dist((a.x, a.y), (b.x, b.y)) < 0.01 and \
        abs(angle_diff_deg(a.heading_deg, b.heading_deg)) < 0.01


@dataclass(frozen=True, slots=True)
class BeliefMemory:
    """The pose belief as a restarted navigation takes it up (kept in `NavMemory.belief`)."""

    belief: PoseBelief
    """The belief (map frame)."""
    dead: DeadReckoning | None
    """The particle set moved by the counts alone (`Localiser._dead`)."""
    odom: Pose
    """The own-frame pose (Motor Control's) both were last moved to."""


class Localiser:
    """The pose belief of the hider's or seeker's navigation (see the module docstring).

    Args:
        nav: the navigation actor whose pose, origin, map and last motion it reads, and
            whose origin it sets.
    """

    def __init__(self, nav: RouteNav) -> None:
        self.nav = nav
        self.belief: PoseBelief | None = None
        """The pose belief (map frame); None until origin and pose are known."""
        self._rng = np.random.default_rng(zlib.crc32(f"belief:{self.nav.role}".encode()))
        self._belief_odom: Pose | None = None  # own-frame pose the belief was last moved to
        self._reports = [TreadReport.OK, TreadReport.OK]  # tread reports since then
        self._reported_before = (False, False)  # each tread reported in the motion before
        self._modelled: tuple[float, float] | None = None  # Motor Control's driven travel [cm]
        self._reported_motion: Motion | None = None  # its NAV_TREAD_DRIVEN is still to come
        self._spread: Spread | None = None  # cached until the belief changes
        self._modes = 1  # clusters of the last spread computed
        self._weighed = False  # an update since the last spread told the particles apart
        self._field: DistanceField | None = None
        self._field_of: GridMap | None = None
        self._dead: DeadReckoning | None = None  # the belief moved by the counts alone
        # its own generator: the belief's draws do not depend on whether it is kept
        self._dead_rng = np.random.default_rng(
            zlib.crc32(f"dead reckoning:{self.nav.role}".encode()))
        given = self.nav.memory.given
        self._given: Pose | None = Pose(*given) if given is not None else None
        # the server's origin the belief started from
        kept = self.nav.memory.belief
        if isinstance(kept, BeliefMemory):  # a restart: go on from what was learned
            self.belief, self._dead, self._belief_odom = kept.belief, kept.dead, kept.odom

    # ------------------------------------------------------------------ reading
    @property
    def spread(self) -> Spread | None:
        """The belief's published spread (None before the belief exists)."""
        if self.belief is None:
            return None
        if self._spread is None:
            self._spread = self.belief.spread()
            self._modes = len(self._spread.clusters)
            self._weighed = False
        return self._spread

    @property
    def drift_cm(self) -> float:
        """How far the map-frame pose may be off [cm]: the belief's 95 % radius."""
        s = self.spread
        return 0.0 if s is None else s.radius95_cm

    def _distance_field(self) -> DistanceField | None:
        if self.nav.map is None:
            return None
        if self._field_of is not self.nav.map:
            self._field, self._field_of = DistanceField.from_grid(self.nav.map), self.nav.map
        return self._field


    # ------------------------------------------------------------------ filtering
    def adopt(self, belief: PoseBelief) -> None:
        """Take ``belief`` (map frame) as the pose belief at the current own-frame pose: the
        next pose at rest moves it by what Motor Control counted since."""
        self.belief, self._belief_odom, self._spread, self._modes = belief, self.nav.pose, None, 1
        self._weighed = False

    def forget_belief(self) -> None:
        """The map-frame pose is given anew (the server's origin): start a new belief."""
        self.belief, self._spread, self._belief_odom, self._modes = None, None, None, 1
        self._weighed = False
        self._dead = None
        self._reports = [TreadReport.OK, TreadReport.OK]
        self._reported_before = (False, False)
        self._modelled = self._reported_motion = None
        self._retain()

    def on_server_origin(self) -> None:
        """The server sent ``origin`` (its start pose for this rover; the base has set it).

        A new origin starts a new belief round it. The same origin again is the
        server's habit of sending it with every ``hide``: a retried destination. It
        says nothing new about where the rover is, so it must not narrow the belief
        to the start's 1 cm / 1 deg round dead reckoning (a retry surer than the try
        that failed). Nor is the belief kept as it is: the route was given up after
        its contacts, which may have led it astray. The retry's belief is the mixture
        of the belief and dead reckoning alone (the same motions, no measurement),
        ``RETRY_PRIOR_SHARE`` of its weight on the latter: every hypothesis either
        holds is kept, so it is never narrower than either.
        """
        given = self.nav.origin
        if (given is not None and self.belief is not None and self._dead is not None
                and self._given is not None and _same_pose(given, self._given)):
            self.track_belief()
            self.belief = self.belief.mixed_with(self._dead.belief, RETRY_PRIOR_SHARE,
                                                 self._rng)
            self._weigh_free_space()  # the rover stands on free ground, whichever is right
            _ = self.spread  # count the hypotheses: the pose is the heaviest one's
            self._sync_origin()
            self.nav.counters["retry_widened"] = self.nav.counters.get("retry_widened", 0) + 1
            return
        self._given = given
        self.forget_belief()
        self.track_belief()

    def note_tread_fault(self, fault: TreadFault) -> None:
        """Motor Control reported a tread during the motion in flight: the next
        prediction samples that tread's travel between its count and its drive."""
        kind = TreadReport.SHORT if fault.counts_short else TreadReport.SILENT
        for t, reported in enumerate(fault.treads):
            if reported and self._reports[t] != TreadReport.SILENT:
                self._reports[t] = kind
        self._reported_motion = self.nav.last_motion

    def note_tread_driven(self, left_cm: float, right_cm: float) -> None:
        """Motor Control's drive model says how far each tread went in the motion that
        ended (``NAV_TREAD_DRIVEN``): the far end of a reported tread's travel. Sent
        without a report for a turn that ended blocked: a rover jammed in a turn and one
        whose encoders both stopped read the same, so both treads' travel lies between
        their counts and the model."""
        m = self.nav.last_motion
        if self._reports == [TreadReport.OK, TreadReport.OK] and m is not None \
                and m.kind == "turn":
            self._reports = [TreadReport.SHORT, TreadReport.SHORT]
        self._modelled = (left_cm, right_cm)
        self._reported_motion = None

    def track_belief(self) -> None:
        """At a pose at rest: move the belief by the motion since the last one, weigh it
        by free space, and read the origin from it."""
        if self.nav.origin is None or not self.nav.pose_known:
            return
        if self.belief is None or self._belief_odom is None:
            self.belief = PoseBelief.around(self.nav.map_pose, self._rng, sigma_cm=START_SIGMA_CM,
                                             sigma_deg=START_SIGMA_DEG)
            self._dead = DeadReckoning(PoseBelief(self.belief.particles))
            self._belief_odom, self._spread = self.nav.pose, None
            self._retain()
            return
        if not self._predict():
            return  # nothing moved: the free-space evidence is in already
        self._weigh_free_space()
        self._sync_origin()

    def _weigh_free_space(self) -> None:
        """Weigh the belief by the free-space model on the server's map (if any)."""
        field = self._distance_field()
        if field is not None and self.belief is not None:
            body = (self.nav.length_cm, self.nav.width_cm)
            ll = free_space_log_likelihood(field, self.belief.particles, body)
            self.belief.update(ll, self._rng)
            # a flat likelihood changes no weight: it cannot split the belief
            self._weighed = self._weighed or bool(ll.min() < ll.max())
        self._spread = None

    def _predict(self) -> bool:
        """Move the belief by the counted motion since the last prediction; False when
        there was none."""
        assert self.belief is not None and self._belief_odom is not None
        if self._reported_motion is not None and self._reported_motion is self.nav.last_motion:
            return False  # the reported motion's driven travel comes with its end
        w = self.nav.spec.track_width_cm
        left, right = tread_travel(self._belief_odom, self.nav.pose, w)
        if abs(left) + abs(right) < 1e-6 and self._reports == [TreadReport.OK, TreadReport.OK]:
            return False
        driven: list[float | None] = [None, None]
        if self._reports != [TreadReport.OK, TreadReport.OK]:
            driven = self._driven(left, right, w)
        motion = TreadMotion(left, right, driven[0], driven[1], *self._reports,
                             *self._reported_before)
        before = self.belief.particles
        self.belief.predict(motion, w, self.nav.o.motion, self._rng)
        field = self._distance_field()
        if field is not None:
            body = (self.nav.length_cm, self.nav.width_cm)
            self.belief.reposition(slide_along_faces(field, before, self.belief.particles,
                                                     body, BOTH_MOVE_RATIO))
        if self._dead is not None:
            self._dead.predict(motion, w, self.nav.o.motion, self._dead_rng)
        self._belief_odom, self._spread = self.nav.pose, None
        self._reported_before = (self._reports[0] != TreadReport.OK,
                                 self._reports[1] != TreadReport.OK)
        self._reports = [TreadReport.OK, TreadReport.OK]
        self._modelled = self._reported_motion = None
        return True

    def _driven(self, left: float, right: float, w: float) -> list[float | None]:
        """Modelled travel [cm] of each reported tread: Motor Control's drive model
        (`note_tread_driven`), at least the count; without it (the message was lost)
        the other tread's count in size when that one counted well, else the last
        motion's commanded travel."""
        counts = (left, right)
        if self._modelled is not None:
            return [None if self._reports[t] == TreadReport.OK else
                    math.copysign(max(abs(self._modelled[t]), abs(counts[t])), self._modelled[t])
                    for t in (0, 1)]
        m = self.nav.last_motion
        if m is None:
            sign, size = (1.0, 1.0), 0.0
        elif m.kind == "turn":
            sign = (-1.0, 1.0) if m.amount >= 0 else (1.0, -1.0)
            size = 0.5 * w * math.radians(abs(m.amount))
        else:
            sign = (1.0, 1.0) if m.amount >= 0 else (-1.0, -1.0)
            size = abs(m.amount)
        out: list[float | None] = [None, None]
        for t in (0, 1):
            if self._reports[t] == TreadReport.OK:
                continue
            other = 1 - t
            ref = abs(counts[other]) if self._reports[other] == TreadReport.OK else size
            out[t] = sign[t] * max(ref, abs(counts[t]))
        return out

    def _sync_origin(self) -> None:
        """The origin that makes the map-frame pose the belief's estimate: the heaviest
        hypothesis's mean while the belief has several, else the mean.

        The hypotheses are counted anew (the clusters cost 0.6 to 2 ms; the mean 10 us)
        whenever the belief had several at the last count, or an update since told its
        particles apart (a contact, or free space cutting off part of the cloud): only a
        weighing splits a belief, the motion model's noise does not. Counting them only
        when something else asked for the spread would leave the pose at the mean of a
        belief already split, between its hypotheses, a pose neither explains.
        """
        if self.belief is None:
            return
        if self._modes > 1 or self._weighed:
            s = self.spread
            assert s is not None
            target = s.best.pose
        else:
            target = self.belief.mean_pose()
        origin = compose(target, inverse(self.nav.pose))
        self.nav.set_origin(origin)
        self._retain()

    def _retain(self) -> None:
        """Keep the belief and the origin it started from in the retained `NavMemory`."""
        g = self._given
        self.nav.memory.given = None if g is None else (g.x, g.y, g.heading_deg)
        self.nav.memory.belief = None if self.belief is None or self._belief_odom is None else \
            BeliefMemory(self.belief, self._dead, self._belief_odom)

    def contact_update(self) -> bool:
        """After a straight move ended blocked: weigh the belief by the contact model.

        Returns:
            True when the map's walls explain the stop (the belief was updated) and
            the heaviest hypothesis moved the pose by more than half a cell or
            ``heading_tol_deg``;
            False when something unmapped explains it better, or the pose stays.
        """
        m, start = self.nav.last_motion, self.nav.motion_from
        field = self._distance_field()
        if (m is None or m.kind != "move" or m.amount == 0 or start is None or field is None
                or self.belief is None):
            return False
        self.track_belief()
        before = self.nav.map_pose
        direction = 1 if m.amount > 0 else -1
        side = stalled_side(angle_diff_deg(before.heading_deg, start.heading_deg), direction)
        o, body = ContactOptions(), (self.nav.length_cm, self.nav.width_cm)
        particles = self.belief.particles
        gap = contact_gap_cm(field, particles, body, direction, side)
        touch = float(self.belief.weights @ np.exp(-0.5 * (gap / o.sigma_cm) ** 2))
        if touch <= o.unmapped_weight:
            return False  # the walls explain the stop worse than something unmapped
        self.belief.update(contact_log_likelihood(field, particles, body, direction, side, o),
                           self._rng)
        self._spread = None
        _ = self.spread  # a contact may leave several hypotheses: count them
        self._sync_origin()
        after = self.nav.map_pose
        self.nav.counters["contacts"] += 1
        moved = math.dist((before.x, before.y), (after.x, after.y))
        return moved > 0.5 * field.resolution_cm or \
            abs(angle_diff_deg(after.heading_deg, before.heading_deg)) > self.nav.o.heading_tol_deg
