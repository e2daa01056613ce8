"""Scan-to-map matching: correct a dead-reckoned pose from the LIDAR returns themselves.

Why
    Dead reckoning on the treads drifts (slip), and its heading is quantised:
    one Int E of one tread turns the estimate by ``cm_per_interrupt /
    track_width`` (0.5 / 13 rad, about 2.2 [deg]), so during a move the
    heading flickers by that much from tick to tick. At 3 m a 2 [deg] error
    puts a wall 10 cm (two cells) off: the map smears. Matching each scan
    against the map built so far puts it where it fits, which is what the
    firmware can do with its own sensors only.

Algorithm
    Gauss-Newton scan-to-map registration as in Hector SLAM (Kohlbrecher et
    al., "A Flexible and Scalable SLAM System with Full 3D Motion Estimation",
    SSRR 2011): minimise ``sum_i (1 - M(S_i(pose)))**2`` over the pose, where
    ``S_i`` puts hit ``i`` (rover frame) into the map frame and ``M`` is a
    smoothed occupancy field, read with bilinear interpolation so it has a
    gradient. Two passes: a wide blur first (a basin of about three cells),
    then a narrow one (precision). Levenberg damping keeps a direction the
    scan does not constrain (one straight wall) at the guess. The result is
    refused (the guess kept) when too few hits, when too few of them land on
    mapped obstacles, or when it fits the map worse than the guess. How far a
    match may move from the guess is not judged here: the mapper's pose belief
    judges it (`localisation.scan_likelihood.judge_fit`), and ``max_shift_cm``
    / ``max_turn_deg`` say how far from the guess this local search reaches
    (beyond, the wide search `relocalise`).

Frame and units
    Map frame [cm], poses as `odometry.Pose` (heading [deg]); fields are crops
    of the grid, cell ``[row, col]`` as in `occupancy`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from actors.firmware import ndimage
from actors.firmware.arrays import pad_border
from actors.firmware.scan_hits import MAX_RANGE_CM, MIN_JUDGED, MIN_POINTS, MIN_RANGE_CM
from server.protocol.pose import Pose

__all__ = ["MatchOptions", "MatchResult", "OccupancyField", "MatchFields", "hits_to_local",
           "match_scan", "relocalise", "ITERATIONS", "BLUR_WIDE",
           "BLUR_NARROW", "DAMPING", "MIN_POINTS", "MIN_JUDGED", "MAX_RANGE_CM",
           "RELOCALISE_TURN_DEG", "RELOCALISE_STEP_DEG", "RELOCALISE_MARGIN"]


# Structural constants of the Gauss-Newton registration and of its verdict: the solver's
# iteration count, blur passes and damping, and the least evidence a scan must bring; no
# rover team tunes these, and a different rover changes none of them.
ITERATIONS = 4
"""Gauss-Newton iterations per blur level."""
BLUR_WIDE = 4
"""Passes of the [1, 2, 1] blur for the first (wide basin) level: a basin of about three
cells."""
BLUR_NARROW = 1
"""Passes of the [1, 2, 1] blur for the final level."""
DAMPING = 0.05
"""Levenberg damping, relative to the diagonal of the normal matrix."""


@dataclass(frozen=True, slots=True)
class MatchOptions:
    """Physical quantities of `match_scan`."""

    max_shift_cm: float = 12.0
    """How far from the guess the local match reaches in position [cm]: the wide field's
    basin (about three cells) with a margin. A pose belief whose 95 % radius is wider
    is searched by `relocalise`."""
    max_turn_deg: float = 6.0
    """How far from the guess the local match reaches in heading [deg]: the basin's
    three cells seen at 1.5 m. A pose belief whose 95 % heading is wider is searched by
    `relocalise`."""
    min_range_cm: float = MIN_RANGE_CM
    """Hits nearer than this are ignored [cm] (too close to tell direction well)."""
    prior_per_point: float = 2e-4
    """Pull toward the guess per hit [1/cm^2] (heading: times the hits' mean square range):
    a direction the scan does not constrain (along one straight wall) stays where dead
    reckoning put it instead of sliding on noise."""

    def __post_init__(self) -> None:
        if not (self.max_shift_cm > 0 and self.max_turn_deg > 0):
            raise ValueError(f"max_shift_cm and max_turn_deg must be > 0, got "
                             f"{self.max_shift_cm!r}, {self.max_turn_deg!r}")
        if not (self.min_range_cm >= 0 and self.prior_per_point >= 0):
            raise ValueError(f"min_range_cm and prior_per_point must be >= 0, got "
                             f"{self.min_range_cm!r}, {self.prior_per_point!r}")


@dataclass(frozen=True, slots=True)
class MatchResult:
    """What `match_scan` found."""

    pose: Pose
    """The pose to use: the match, or the guess when the match was refused."""
    accepted: bool
    """Whether ``pose`` is the match (False: it is the guess)."""
    score_guess: float
    """Mean narrow-field value at the hits from the guess, 0..1."""
    score: float
    """Mean narrow-field value at the hits from ``pose``, 0..1."""
    reason: str = ""
    """Why the match was refused (empty when accepted)."""
    supported: bool = False
    """Whether enough hits fell on mapped obstacles to judge the scan: a supported scan
    that was refused (a worse fit, an ambiguous view) is suspect, its pose unknown."""


def _binomial(passes: int) -> np.ndarray:
    """The 1-D kernel of ``passes`` [1, 2, 1] / 4 blurs (binomial, sums to 1)."""
    k = np.array([1.0])
    for _ in range(passes):
        k = np.convolve(k, [0.25, 0.5, 0.25])
    return k


def _blur(field: np.ndarray, passes: int) -> np.ndarray:
    """Separable binomial blur equal to ``passes`` [1, 2, 1] / 4 blurs (zeros outside):
    one `scipy.ndimage.correlate1d` per axis (`actors.firmware.ndimage`)."""
    if passes == 0:
        return field.copy()
    k = _binomial(passes)
    rows = ndimage.correlate1d(field, k, axis=1, mode="constant")
    return ndimage.correlate1d(rows, k, axis=0, mode="constant")


class OccupancyField:
    """A smoothed occupancy field over a crop of a grid, scaled so a wall's ridge is 1.

    Args:
        occupied: (ny, nx) crop: True (or a weight 0..1) where returns are expected.
        origin_cm: lower-left corner of the crop's cell [0, 0] [cm].
        resolution_cm: cell side [cm].
        passes: [1, 2, 1] blur passes (wider basin, less precision).
    """

    def __init__(self, occupied: np.ndarray, origin_cm: tuple[float, float],
                 resolution_cm: float, passes: int) -> None:
        peak = float(_binomial(passes).max())  # what a one-cell line keeps across it
        f = np.minimum(_blur(np.asarray(occupied, dtype=np.float64), passes) / peak, 1.0)
        # a border of zeros: points outside read 0 with no gradient
        self.values = pad_border(f)
        """Field values (ny + 2, nx + 2), 0..1, with a zero border."""
        self._flat = self.values.ravel()
        self.origin_cm = (origin_cm[0] - resolution_cm, origin_cm[1] - resolution_cm)
        """Lower-left corner of ``values``' cell [0, 0] [cm] (the border included)."""
        self.resolution_cm = resolution_cm
        ny, nx = self.values.shape
        self._nx = nx
        # the four nodes around a point, as views: node i, i + 1, i + nx, i + nx + 1
        self._right = self._flat[1:]
        self._up = self._flat[nx:]
        self._up_right = self._flat[nx + 1:]
        self._node0 = np.array([[self.origin_cm[0] + 0.5 * resolution_cm],
                                [self.origin_cm[1] + 0.5 * resolution_cm]])
        self._node_max = np.array([[nx - 1.000001], [ny - 1.000001]])

    def sample(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Bilinear value and gradient [1/cm] at points (x, y) [cm]; 0 outside the crop."""
        return self.sample_xy(np.stack([np.asarray(x, dtype=np.float64),
                                        np.asarray(y, dtype=np.float64)]))

    def sample_xy(self, xy: np.ndarray, out: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """`sample` of points stacked as rows x and y, (2, n) [cm]; ``xy`` is overwritten.

        Both axes go through each numpy call at once: with about a hundred hits
        per scan the calls' overhead, not the arithmetic, is the cost. With ``out``
        (3, n), the value and the gradient are written into its rows (and returned
        as views of them).
        """
        inv = 1.0 / self.resolution_cm
        fx, fy, a, b, v10, top = self._lerp(xy, inv)
        if out is None:
            vert = v10 + b * fx - top
            return top + vert * fy, (a + (b - a) * fy) * inv, vert * inv
        # the same operations written in place into the rows of ``out``
        val, dx, dy = out[0], out[1], out[2]
        np.multiply(b, fx, out=dy)
        dy += v10
        dy -= top  # vert
        np.multiply(dy, fy, out=val)
        val += top
        np.subtract(b, a, out=dx)
        dx *= fy
        dx += a
        out[1:3] *= inv  # both gradient rows at once
        return val, dx, dy

    def value_xy(self, xy: np.ndarray) -> np.ndarray:
        """`sample_xy`'s value alone (the same floats), without the gradient's work;
        ``xy`` is overwritten."""
        fx, fy, _, b, v10, top = self._lerp(xy, 1.0 / self.resolution_cm)
        return top + (v10 + b * fx - top) * fy

    def _lerp(self, xy: np.ndarray, inv: float) -> tuple[np.ndarray, ...]:
        """The interpolation's first half at points ``xy`` (2, n) [cm] (overwritten),
        ``inv`` the inverse cell side: the fractions fx, fy within the cell, the
        differences a (lower nodes) and b (upper nodes) along x, the upper-left node's
        value and the lower edge's value at fx (``top``)."""
        # cell centres are the interpolation nodes: to node units, clamped to the crop
        g = np.subtract(xy, self._node0, out=xy)
        g *= inv
        np.maximum(g, 0.0, out=g)
        np.minimum(g, self._node_max, out=g)
        cr = g.astype(np.int64)
        frac = g - cr
        fx, fy = frac[0], frac[1]
        i = cr[1] * self._nx + cr[0]
        v00, v10 = self._flat[i], self._up[i]
        a = self._right[i] - v00
        b = self._up_right[i] - v10
        return fx, fy, a, b, v10, v00 + a * fx


def usable_hits(ranges_cm: np.ndarray, options: MatchOptions) -> np.ndarray:
    """Which beams are hits usable for matching: within ``min_range_cm`` and
    `MAX_RANGE_CM` (a boolean mask)."""
    r = np.asarray(ranges_cm, dtype=np.float64)
    return (r >= options.min_range_cm) & (r <= MAX_RANGE_CM)


def hits_to_local(angles_deg: np.ndarray, ranges_cm: np.ndarray, options: MatchOptions
                  ) -> np.ndarray:
    """Hits usable for matching (`usable_hits`) as points (n, 2) in the rover frame [cm]."""
    r = np.asarray(ranges_cm, dtype=np.float64)
    a = np.radians(np.asarray(angles_deg, dtype=np.float64))
    keep = usable_hits(r, options)
    r, a = r[keep], a[keep]
    pts = np.empty((r.size, 2))  # the columns written in place (not `np.column_stack`)
    np.multiply(r, np.cos(a), out=pts[:, 0])
    np.multiply(r, np.sin(a), out=pts[:, 1])
    return pts


def _homogeneous(pts: np.ndarray) -> np.ndarray:
    """Hits (n, 2) as the rows x, y, 1 of a (3, n) array: a pose's (2, 3) matrix
    ``[[c, -s, x], [s, c, y]]`` times it puts them in the map frame in one product."""
    hom = np.ones((3, len(pts)))
    hom[:2] = pts.T
    return hom


def _solve3(h: list[list[float]], g: list[float]) -> tuple[float, float, float] | None:
    """Solve the symmetric 3 x 3 system ``h @ x = g`` (Cramer's rule); None if singular."""
    (a, b, c), (_, e, f), (_, _, i) = h
    co0, co1, co2 = e * i - f * f, c * f - b * i, b * f - c * e
    det = a * co0 + b * co1 + c * co2
    if not (abs(det) > 1e-300 and math.isfinite(det)):
        return None
    g0, g1, g2 = g
    x0 = (g0 * co0 + g1 * co1 + g2 * co2) / det
    x1 = (g0 * co1 + g1 * (a * i - c * c) + g2 * (b * c - a * f)) / det
    x2 = (g0 * co2 + g1 * (b * c - a * f) + g2 * (a * e - b * b)) / det
    return x0, x1, x2


def _gauss_newton(field: OccupancyField, hom: np.ndarray, pose: np.ndarray, guess: np.ndarray,
                  iterations: int, damping: float, prior: np.ndarray) -> np.ndarray:
    """Damped Gauss-Newton with a quadratic pull ``prior`` (diagonal) toward ``guess``.

    Each iteration is a few stacked products: the hits (``hom``, see `_homogeneous`)
    are turned as one (2, 3) x (3, n) product; the field writes its value and gradient
    into the rows of one (4, n) array ``jr`` that then holds the residual and the
    Jacobian rows (d/dx, d/dy, d/dtheta), and ``jr[1:] @ jr.T`` is the normal matrix
    and the gradient at once; the 3 x 3 system is solved in closed form. With about a
    hundred hits the numpy call overhead, not the arithmetic, is the cost.
    """
    x, y, th = pose.tolist()
    gx0, gy0, gth0 = guess.tolist()
    jr = np.empty((4, hom.shape[1]))  # rows: the residual (first the field's value), d/dx,
    # d/dy, d/dtheta
    r, mx, my, dth = jr
    lx, ly, lth = prior.tolist()
    turn = np.zeros((2, 3))  # [[c, -s, 0], [s, c, 0]], filled in per iteration
    shift = np.empty((2, 1))  # [[x], [y]]
    xy = np.empty((2, hom.shape[1]))  # the hits in the map frame (sample_xy overwrites it)
    for _ in range(iterations):
        c, s = math.cos(th), math.sin(th)
        turn[0, 0] = turn[1, 1] = c
        turn[0, 1] = -s
        turn[1, 0] = s
        rot = turn @ hom  # the hits rotated, rover-relative
        shift[0, 0] = x
        shift[1, 0] = y
        field.sample_xy(np.add(rot, shift, out=xy), out=jr[:3])
        np.subtract(my * rot[0], mx * rot[1], out=dth)
        np.subtract(1.0, r, out=r)
        (gx, hxx, hxy, hxt), (gy, _, hyy, hyt), (gt, _, _, htt) = (jr[1:] @ jr.T).tolist()
        h = [[hxx * (1 + damping) + lx + 1e-9, hxy, hxt],
             [hxy, hyy * (1 + damping) + ly + 1e-9, hyt],
             [hxt, hyt, htt * (1 + damping) + lth + 1e-9]]
        g = [gx - lx * (x - gx0), gy - ly * (y - gy0), gt - lth * (th - gth0)]
        step = _solve3(h, g)
        if step is None or not (math.isfinite(step[0]) and math.isfinite(step[1])
                                and math.isfinite(step[2])):
            break
        x, y, th = x + step[0], y + step[1], th + step[2]
        if abs(step[0]) + abs(step[1]) < 0.05 and abs(step[2]) < 1e-4:
            break
    return np.array([x, y, th])


class MatchFields:
    """The wide and narrow fields of one map, built once and matched against many scans.

    Args:
        occupied: (ny, nx): the map's occupied cells, bool or weights 0..1 (a crop is
            fine).
        origin_cm: lower-left corner of ``occupied``'s cell [0, 0] [cm].
        resolution_cm: cell side [cm].
    """

    def __init__(self, occupied: np.ndarray, origin_cm: tuple[float, float],
                 resolution_cm: float) -> None:
        occ = np.asarray(occupied, dtype=np.float64)
        self.empty = not occ.any()
        """True when the map has no obstacle to match against."""
        self.wide = OccupancyField(occ, origin_cm, resolution_cm, BLUR_WIDE)
        self.narrow = OccupancyField(occ, origin_cm, resolution_cm, BLUR_NARROW)


def _score(fields: MatchFields, hom: np.ndarray, x: float, y: float, theta: float
           ) -> tuple[float, float]:
    """How well the hits (``hom``, see `_homogeneous`) placed at (x, y, theta) fit the map:
    the mean of the narrow field, and the share of hits on a mapped obstacle (field above
    0.25)."""
    c, s = math.cos(theta), math.sin(theta)
    m = fields.narrow.value_xy(np.array([[c, -s, x], [s, c, y]]) @ hom)
    n = m.size
    # the ufuncs' own reductions: what ``m.sum()`` runs, without its Python wrapper
    return float(np.add.reduce(m)) / n, float(np.count_nonzero(m > 0.25)) / n


def _prior(pts: np.ndarray, o: MatchOptions) -> np.ndarray:
    """The pull toward the starting pose per (x, y, theta), scaled by the hit count
    (theta also by the hits' mean squared range)."""
    a = o.prior_per_point * len(pts)
    # the mean as ``np.mean`` computes it (its sum, then one division), without its wrapper
    return np.array([a, a, a * (float(np.add.reduce(pts[:, 0] ** 2 + pts[:, 1] ** 2))
                                / len(pts))])


def _fit(fields: MatchFields, hom: np.ndarray, start: np.ndarray, prior: np.ndarray,
         o: MatchOptions) -> tuple[np.ndarray, float, float]:
    """Gauss-Newton from ``start`` (wide, then narrow); the pose, its score and support."""
    est = _gauss_newton(fields.wide, hom, start, start, ITERATIONS, DAMPING, prior)
    est = _gauss_newton(fields.narrow, hom, est, start, ITERATIONS, DAMPING, prior)
    return (est, *_score(fields, hom, est[0], est[1], est[2]))


def match_scan(fields: MatchFields, points: np.ndarray, guess: Pose,
               options: MatchOptions | None = None) -> MatchResult:
    """Register scan hits against the map, starting from ``guess``.

    Args:
        fields: the map's fields (see `MatchFields`).
        points: hits in the rover frame, (n, 2) [cm] (see `hits_to_local`).
        guess: where dead reckoning says the rover was (map frame).
        options: tunables.

    Returns:
        The match, or the guess with the reason it was refused.
    """
    o = options or MatchOptions()
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(pts) < MIN_POINTS:
        return MatchResult(guess, False, 0.0, 0.0, f"{len(pts)} hits, need {MIN_POINTS}")
    if fields.empty:
        return MatchResult(guess, False, 0.0, 0.0, "no mapped obstacle to match against")
    theta0 = guess.heading_rad
    hom = _homogeneous(pts)
    score0, support0 = _score(fields, hom, guess.x, guess.y, theta0)
    start = np.array([guess.x, guess.y, theta0])
    est, score1, support1 = _fit(fields, hom, start, _prior(pts, o), o)
    if max(support0, support1) < MIN_JUDGED:
        return MatchResult(guess, False, score0, score0,
                           f"only {max(support0, support1):.0%} of the hits on mapped obstacles")
    if score1 < score0:
        return MatchResult(guess, False, score0, score0, "the match fits worse than the guess",
                           True)
    return MatchResult(Pose(float(est[0]), float(est[1]), math.degrees(est[2])), True,
                       score0, score1, "", True)


# The search of `relocalise` and its verdict: the fan of starting headings (within the
# wide field's basin of each other) and how clearly the winner must win; structural, like
# the solver's constants above.
RELOCALISE_TURN_DEG = 24.0
"""Search headings up to this far either side of the guess by default [deg]; the mapper
searches its belief's 95 % heading (`map_management`)."""
RELOCALISE_STEP_DEG = 3.0
"""Between the headings tried [deg] (within the wide field's basin of each other)."""
RELOCALISE_MARGIN = 0.08
"""The winner (``MIN_JUDGED`` of its hits on mapped obstacles, as for every match) must
beat any other fit more than 2 ``RELOCALISE_STEP_DEG`` away in heading
(the guess among them, when the winner lies that far from it) by this much (an ambiguous
view, such as a round wall, is not re-localised)."""


def relocalise(fields: MatchFields, points: np.ndarray, guess: Pose,
               options: MatchOptions | None = None, *,
               turn_deg: float = RELOCALISE_TURN_DEG,
               max_shift_cm: float = 40.0) -> MatchResult:
    """A wider search than `match_scan`, for a pose odometry has lost (a stuck or slipping
    encoder turned the rover where dead reckoning did not, or the other way round).

    Why: `match_scan`'s Gauss-Newton starts from the guess and reaches about
    ``max_turn_deg`` from it; a pose further off (a belief widened by a tread fault) lies
    outside its basin. Here Gauss-Newton starts from headings every ``RELOCALISE_STEP_DEG`` within
    ``turn_deg`` of the guess; the best fit is accepted only when it is supported
    (``MIN_JUDGED``), clearly better than the guess and unambiguous
    (``RELOCALISE_MARGIN``). How well it fits in itself is judged where every placement
    is (`localisation.scan_likelihood.judge_fit`: ``MIN_FIT``). Use it while the rover
    stands.

    Args:
        fields: the map's fields.
        points: hits in the rover frame, (n, 2) [cm].
        guess: dead reckoning's pose (map frame).
        options: matching's quantities (the hits' range, the prior).
        turn_deg: search headings up to this far either side of the guess [deg].
        max_shift_cm: fits further than this from the guess are not taken [cm] (the
            mapper passes its belief's 95 % radius).

    Returns:
        The re-localised pose (accepted), or the guess with the reason it was refused.
    """
    o = options or MatchOptions()
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(pts) < MIN_POINTS or fields.empty:
        return MatchResult(guess, False, 0.0, 0.0, "too few hits or nothing mapped")
    theta0 = guess.heading_rad
    hom = _homogeneous(pts)
    score0, _ = _score(fields, hom, guess.x, guess.y, theta0)
    prior = _prior(pts, o)
    n = int(turn_deg // RELOCALISE_STEP_DEG)
    fits = []
    for k in range(-n, n + 1):
        start = np.array([guess.x, guess.y, theta0 + math.radians(k * RELOCALISE_STEP_DEG)])
        est, score, support = _fit(fields, hom, start, prior, o)
        if math.hypot(est[0] - guess.x, est[1] - guess.y) <= max_shift_cm:
            fits.append((score, support, est))
    if not fits:
        return MatchResult(guess, False, score0, score0, "no fit near the guess", True)
    score, support, est = max(fits, key=lambda f: f[0])
    # the pull toward each start biases its fit: polish the winner from where it ended
    est, score, support = _fit(fields, hom, est, prior, o)
    rivals = [f[0] for f in fits
              if abs(math.degrees(f[2][2] - est[2])) > 2.0 * RELOCALISE_STEP_DEG]
    rival = max(rivals, default=0.0)
    if support < MIN_JUDGED:
        return MatchResult(guess, False, score0, score0,
                           f"best fit unsupported ({support:.0%} on obstacles)", True)
    # the guess is a rival only when the winner lies away from it: a wide belief whose
    # mean is right must be able to find its own mean
    near_guess = abs(math.degrees(est[2] - theta0)) <= 2.0 * RELOCALISE_STEP_DEG
    if score < rival + RELOCALISE_MARGIN or (
            not near_guess and score < score0 + RELOCALISE_MARGIN):
        return MatchResult(guess, False, score0, score0,
                           f"ambiguous ({score:.2f} against {max(score0, rival):.2f})", True)
    return MatchResult(Pose(float(est[0]), float(est[1]), math.degrees(est[2])), True,
                       score0, score, "", True)
