"""Tread motion model: sample where each particle went, given the encoder counts.

Why
    A differential-drive rover's odometry errs per tread: each tread's counted
    distance differs from the distance the tread really travelled. Modelling
    the error there, instead of as "degrees of heading doubt", lets the
    heading and position spread follow from the geometry: a tread whose
    travel is in doubt by ``e`` [cm] turns the rover by up to ``e / w`` [rad]
    (``w`` the track width) and moves its centre by ``e / 2``. What Motor
    Control reports about a tread (driven but not counting, counting short,
    both short) widens that tread's travel only, and the spread of the heading
    comes out of it.

Algorithm
    Per particle, per tread ``i`` (left, right), the true travel is sampled:

    * healthy: ``counted_i + N(0, encoder_sigma**2 * |counted_i|)``. The
      variance grows linearly with the distance, so the spread after a path
      does not depend on how it was cut into steps (the same holds for the
      world's slip, `world.drive`);
    * reported (silent or short): ``counted_i + u * (driven_i * (1 + N(0,
      driven_sigma**2)) - counted_i)``. Motor Control cannot tell the two
      explanations of a report apart, and the faults that cause one are of
      two kinds: the count is right (a weak or stalled motor, a tread
      blocked) and ``u = 0``; or the model is right (a slipping or stuck
      encoder: the tread went as driven) and ``u = 1``. Each explanation has
      half the particles (``u`` uniform: under 1/2 the first, else the
      second). A fault begins within the first motion it is reported in, so
      there the second explanation holds from an onset anywhere in the
      motion, ``u ~ Uniform(0, 1)``; a motion after one with the same tread
      reported is all after the onset (``TreadMotion.left_continued``). So
      the belief keeps two narrow hypotheses, which the free-space model and
      contacts tell apart, instead of one smeared between them whose middle
      no fault explains. When both treads are reported, one ``u`` (and one
      draw of the model's error) per particle serves both (two encoders
      slipping alike, or two motors weak alike, keep the treads alike: a
      straight move stays straight and a turn scales as a whole).

    Then the pose advances by the midpoint rule of `odometry.advance`,
    vectorised (``dtheta = (dr - dl) / w``, ``ds = (dr + dl) / 2`` along
    ``theta + dtheta / 2``), and the heading gets the treads' scrub on the
    floor while turning: ``N(0, turn_sigma**2 * |dtheta|)`` [deg].

    The fault draw ``u`` is one per call: a slipping encoder's ratio holds
    over a motion, so call this once per motion (Motor Control's report is per
    command); the healthy terms may be applied in steps of any length.

Reference
    Thrun, Burgard, Fox, *Probabilistic Robotics*, section 5.4
    (``sample_motion_model_odometry``), whose four ``alpha`` coefficients Nav2
    AMCL uses; here the same idea per tread, as a tracked rover errs per tread.
    PythonRobotics ``Localization/particle_filter`` (motion model plus named
    input noise).

Frame and units
    Particles are an (N, 3) float array of ``x`` [cm], ``y`` [cm], heading
    ``theta`` [rad] in the map frame; tread distances [cm], signed (negative
    backwards).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from actors.firmware.drivers.tread_monitor import MODEL_SIGMA

__all__ = ["TreadReport", "TreadMotion", "MotionNoise", "sample_motion", "reports_from_value"]


class TreadReport(IntEnum):
    """What Motor Control said about one tread during a motion."""

    OK = 0
    """No report: the count is the travel, up to the encoder noise."""
    SILENT = 1
    """Driven but not counting (a stuck encoder, or a stalled motor)."""
    SHORT = 2
    """Counting under its modelled travel (a slipping encoder, or a weak motor)."""


def reports_from_value(value: int) -> tuple[TreadReport, TreadReport]:
    """The (left, right) reports of a ``NAV_TREAD_FAULT`` value.

    The value's bits (see ``drivers/motor.py``): bit 0 the tread (0 left,
    1 right), bit 1 the kind (0 silent, 1 short), bit 2 both treads. So 0/1
    left/right silent, 2/3 left/right short, 4 both silent, 6 both short.

    Raises:
        ValueError: for a value outside 0, 1, 2, 3, 4, 6.
    """
    if value not in (0, 1, 2, 3, 4, 6):
        raise ValueError(f"tread fault value must be 0, 1, 2, 3, 4 or 6, got {value!r}")
    kind = TreadReport.SHORT if value & 2 else TreadReport.SILENT
    if value & 4:
        return kind, kind
    return (TreadReport.OK, kind) if value & 1 else (kind, TreadReport.OK)


@dataclass(frozen=True, slots=True)
class TreadMotion:
    """One motion as Motor Control counted it (the control input of the filter)."""

    left_cm: float
    """Left tread's counted travel [cm], signed."""
    right_cm: float
    """Right tread's counted travel [cm], signed."""
    driven_left_cm: float | None = None
    """Left tread's travel by Motor Control's model of its PWM [cm]; needed when the
    left tread is reported, ignored otherwise."""
    driven_right_cm: float | None = None
    """Right tread's modelled travel [cm]; needed when the right tread is reported."""
    left: TreadReport = TreadReport.OK
    """What Motor Control reported about the left tread in this motion."""
    right: TreadReport = TreadReport.OK
    """What Motor Control reported about the right tread in this motion."""
    left_continued: bool = False
    """The left tread was reported in the motion before too: its fault began before this
    motion, not within it."""
    right_continued: bool = False
    """The right tread was reported in the motion before too."""

    def __post_init__(self) -> None:
        for name in ("left_cm", "right_cm"):
            v = getattr(self, name)
            if not math.isfinite(v):
                raise ValueError(f"TreadMotion.{name} must be finite, got {v!r}")
        for report, driven, name in ((self.left, self.driven_left_cm, "driven_left_cm"),
                                     (self.right, self.driven_right_cm, "driven_right_cm")):
            if report != TreadReport.OK and (driven is None or not math.isfinite(driven)):
                raise ValueError(f"TreadMotion.{name} must be a finite number when that "
                                 f"tread is reported {report.name}, got {driven!r}")


@dataclass(frozen=True, slots=True)
class MotionNoise:
    """Noise levels of the tread motion model (each with its unit)."""

    encoder_sigma: float = 0.025
    """A healthy tread's travel error: standard deviation over 1 cm of travel, growing
    with the square root of the distance [cm / sqrt(cm)] (0.25 cm over 1 m). The
    world's ``slip_sigma`` is the same quantity; a filter should not assume less."""
    turn_sigma: float = 0.2
    """Heading error from the treads scrubbing in a turn: standard deviation over 1 deg
    turned, growing with the square root of the turn [deg / sqrt(deg)] (1.9 deg over a
    90 deg turn)."""
    driven_sigma: float = MODEL_SIGMA
    """Relative error of Motor Control's modelled travel of a reported tread [1]: the
    far end of that tread's range is ``driven * (1 + N(0, driven_sigma**2))``; the tread
    monitor's healthy model (`drivers.tread_monitor.MODEL_SIGMA`)."""

    def __post_init__(self) -> None:
        for name in ("encoder_sigma", "turn_sigma", "driven_sigma"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"MotionNoise.{name} must be a finite number >= 0, got {v!r}")


def _share_driven(u: np.ndarray, continued: bool) -> np.ndarray:
    """The share of a reported tread's modelled travel each particle takes, from its
    uniform draw ``u``: 0 (the count is right) for ``u < 1/2``, else 1 (the model is
    right) or, in the motion the fault began in, the share after a uniform onset."""
    return np.where(u < 0.5, 0.0, 1.0 if continued else 2.0 * u - 1.0)


def _tread_travel(counted: float, driven: float | None, report: TreadReport,
                  u: np.ndarray, continued: bool, z: np.ndarray, noise: MotionNoise,
                  rng: np.random.Generator) -> np.ndarray:
    """Sampled true travel of one tread for ``n = u.size`` particles [cm]; a reported
    tread's share between counted (0) and driven (1) follows from the uniform draw ``u``
    (`_share_driven`, made only for a reported tread), ``z`` is the modelled travel's
    relative error draw."""
    n = u.shape[0]
    travel = counted + rng.standard_normal(n) * (noise.encoder_sigma * math.sqrt(abs(counted)))
    if report == TreadReport.OK:
        return travel
    far = driven * (1.0 + z * noise.driven_sigma)
    return travel + _share_driven(u, continued) * (far - counted)


def sample_motion(particles: np.ndarray, motion: TreadMotion, track_width_cm: float,
                  noise: MotionNoise, rng: np.random.Generator) -> np.ndarray:
    """Move every particle by one motion, each with its own draw of the noise.

    Args:
        particles: (N, 3) ``x`` [cm], ``y`` [cm], ``theta`` [rad], map frame.
        motion: the counted (and, for a reported tread, modelled) tread travel.
        track_width_cm: distance between the treads' contact lines [cm].
        noise: the noise levels.
        rng: the run's generator (the only source of randomness).

    Returns:
        A new (N, 3) array; ``theta`` is not wrapped (wrap where it is read).

    Raises:
        ValueError: for particles not of shape (N, 3) or a non-positive track width.
    """
    p = np.asarray(particles, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"particles must have shape (N, 3), got {p.shape}")
    if not (math.isfinite(track_width_cm) and track_width_cm > 0):
        raise ValueError(f"track_width_cm must be positive, got {track_width_cm!r}")
    n = p.shape[0]
    # the fault draws: which explanation (and where the fault began), and the model's
    # own error;
    # shared by the two treads when both are reported (they err alike)
    u_left, z_left = rng.random(n), rng.standard_normal(n)
    both = motion.left != TreadReport.OK and motion.right != TreadReport.OK
    u_right, z_right = (u_left, z_left) if both else (rng.random(n), rng.standard_normal(n))
    dl = _tread_travel(motion.left_cm, motion.driven_left_cm, motion.left, u_left,
                       motion.left_continued, z_left, noise, rng)
    dr = _tread_travel(motion.right_cm, motion.driven_right_cm, motion.right, u_right,
                       motion.right_continued, z_right, noise, rng)
    dtheta = (dr - dl) / track_width_cm  # [rad]
    ds = 0.5 * (dr + dl)  # [cm]
    mid = p[:, 2] + 0.5 * dtheta
    scrub_deg = rng.standard_normal(n) * (noise.turn_sigma * np.sqrt(np.abs(np.degrees(dtheta))))
    out = np.empty_like(p)
    out[:, 0] = p[:, 0] + ds * np.cos(mid)
    out[:, 1] = p[:, 1] + ds * np.sin(mid)
    out[:, 2] = p[:, 2] + dtheta + np.radians(scrub_deg)
    return out
