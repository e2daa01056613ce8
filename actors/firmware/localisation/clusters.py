"""The hypotheses of a particle belief: modes of the particles' weight, found on a lattice.

Why
    A contact near a corner leaves two groups of particles a few tens of cm
    apart, often with a thin trail of light particles between them.
    Connected cells of a thresholded histogram (AMCL's kd-tree clusters)
    join such groups through the trail, or split one broad group into many
    when the lattice is fine. Modes of a smoothed weight density, joined only
    when the density between them does not dip, separate two hypotheses
    whatever trail lies between, and keep one broad hypothesis whole.

Algorithm
    1. The weights are summed on a lattice of ``CELL_CM`` x ``CELL_CM`` x
       ``CELL_DEG`` (heading periodic) and smoothed with a Gaussian of
       ``SMOOTH_CELLS`` lattice cells: the values of
       ``scipy.ndimage.gaussian_filter``, computed on the lattice lines that
       carry weight only (`_Density`).
    2. Local maxima of the smoothed density (none of the 26 neighbours higher,
       as ``maximum_filter`` finds them) above ``PEAK_FLOOR`` of the highest
       are the candidate modes (at most ``MAX_PEAKS``, highest first).
    3. Two modes are one hypothesis when the density along the straight line
       between them never falls under ``VALLEY`` times the lower of the two
       (a plateau, or a ridge); the joined modes are the connected components
       of that relation (union-find over at most ``MAX_PEAKS`` modes, numbered
       as ``scipy.sparse.csgraph.connected_components`` numbers them: in the
       order of each component's first mode).
    4. Every particle belongs to its nearest mode's hypothesis (lattice
       distance, heading wrapped).

    Every step is vectorised over particles; the only loops are over the
    bounded set of modes (pairs of modes in one array).

Reference
    Fukunaga and Hostetler, "The estimation of the gradient of a density
    function", 1975 (mode seeking); Nav2 AMCL's pose clusters
    (``pf_cluster_stats``) for what a cluster reports.

Frame and units
    Particles (N, 3): ``x``, ``y`` [cm], ``theta`` [rad].
"""

from __future__ import annotations

import math

import numpy as np

from actors.firmware.arrays import nonzero_2d
from actors.firmware.ndimage import correlate1d, gaussian_weights

__all__ = ["cluster_labels", "CELL_CM", "CELL_DEG", "SMOOTH_CELLS", "PEAK_FLOOR", "VALLEY",
           "MAX_PEAKS", "MAX_LATTICE_CELLS"]


# The lattice and thresholds of the mode finding: how the particles are summarised as
# hypotheses, not a property of the rover or of its sensors, so fixed here beside the
# algorithm (they are checked by tests/test_localisation_belief.py and
# tests/test_localisation_contact.py: a corner's two hypotheses stay two, one broad one
# stays one).
CELL_CM = 4.0
"""Position side of the lattice [cm]."""
CELL_DEG = 5.0
"""Heading side of the lattice [deg]."""
SMOOTH_CELLS = 1.0
"""Standard deviation of the smoothing, in lattice cells [1]."""
PEAK_FLOOR = 0.05
"""Modes lower than this share of the highest are not modes [1]."""
VALLEY = 0.5
"""Two modes are one hypothesis unless the density between them dips under this share of
the lower mode [1]."""
MAX_PEAKS = 32
"""At most this many modes are considered, highest first [1]."""
MAX_LATTICE_CELLS = 2_000_000
"""Bound on the lattice: a belief spread wider than this allows is clustered on a coarser
position lattice [cells]."""


_MODES = ("nearest", "nearest", "wrap")  # the heading axis is periodic
_KERNEL = gaussian_weights(SMOOTH_CELLS)
"""``gaussian_filter1d``'s weights for ``SMOOTH_CELLS`` (read-only): computed once, not
for every pass of every clustering."""
_KERNEL.flags.writeable = False
_RADIUS = (_KERNEL.size - 1) // 2
"""The kernel's radius [cells]."""
_LINE_SAMPLES = 16
_LINE_STEPS = np.linspace(0.0, 1.0, _LINE_SAMPLES)
_LINE_STEPS.flags.writeable = False
_PAIRS = np.array(np.triu_indices(MAX_PEAKS, 1))
"""Every pair of modes (i < j < MAX_PEAKS) in np.triu_indices's order (read-only)."""
_PAIRS.flags.writeable = False


_WEAK = 0.9 * float(_KERNEL[_RADIUS]) * PEAK_FLOOR * VALLEY
"""A heading line whose every input lies under this share of the highest input is read as
zeros [1]: nine tenths of the least share of the highest density a join compares with
(see `_Density`)."""
_TINY = 1e-200
"""Where the highest input is below this every line is filtered (the bound would
underflow)."""


def _smooth(values: np.ndarray, axis: int, mode: str) -> np.ndarray:
    """``gaussian_filter1d(values, SMOOTH_CELLS, axis, mode=mode)``: the same weights,
    the same kernel."""
    return correlate1d(values, _KERNEL, axis, mode)


def _clip(values: np.ndarray, high: int) -> np.ndarray:
    """``np.clip(values, 0, high)`` of integers, without its Python wrapper."""
    return np.minimum(np.maximum(values, 0), high)


def cluster_labels(particles: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """The hypothesis of every particle: labels (N,) in 0..K-1, K the hypotheses found.

    Args:
        particles: (N, 3) ``x``, ``y`` [cm], ``theta`` [rad].
        weights: (N,) non-negative weights.
    """
    p = np.asarray(particles, dtype=float)
    w = np.asarray(weights, dtype=float)
    nh = max(1, round(360.0 / CELL_DEG))
    pad = math.ceil(3 * SMOOTH_CELLS) + 1
    # ufunc reductions and array methods, not numpy's Python wrappers round them: a
    # clustering makes about a hundred numpy calls on a few hundred particles (and a
    # column's reduction is several times faster than the (N, 3) array's along axis 0)
    px, py = p[:, 0], p[:, 1]
    x0, y0 = float(px.min()), float(py.min())
    span = max(float(px.max()) - x0, float(py.max()) - y0)
    cell = max(CELL_CM, span / max(math.sqrt(MAX_LATTICE_CELLS / nh) - 2 * pad, 1.0))
    gx = (px - x0) / cell + pad  # lattice coordinates [cells]
    gy = (py - y0) / cell + pad
    gh = (np.degrees(p[:, 2]) % 360.0) / (360.0 / nh)
    ix, iy = gx.astype(np.int64), gy.astype(np.int64)
    ih = gh.astype(np.int64) % nh
    dens = _Density(ix, iy, ih, w, (int(np.maximum.reduce(ix)) + pad + 1,
                                    int(np.maximum.reduce(iy)) + pad + 1, nh))
    if dens.top <= 0.0:
        return np.zeros(p.shape[0], dtype=np.int64)
    coords, values = dens.peaks(PEAK_FLOOR * dens.top)
    order = (-values).argsort(kind="stable")[:MAX_PEAKS]
    coords, values = coords[order].astype(float) + 0.5, values[order]
    comp = _join(dens, coords, values, VALLEY, nh)
    if not comp.any():  # one hypothesis: every particle's nearest mode is in it
        return np.zeros(p.shape[0], dtype=np.int64)
    # nearest mode of each particle, heading wrapped [cells]
    dx = np.subtract.outer(gx, coords[:, 0])
    dy = np.subtract.outer(gy, coords[:, 1])
    dh = _wrapped(np.subtract.outer(gh, coords[:, 2]), nh)
    dx *= dx
    dy *= dy
    dh *= dh
    dx += dy
    dx += dh
    return comp[dx.argmin(axis=1)]


def _wrapped(dh: np.ndarray, nh: int) -> np.ndarray:
    """``(dh + nh / 2) % nh - nh / 2`` for heading differences ``dh`` in ``(-nh, nh)``
    [cells], in place, the same floats: ``x = dh + nh / 2`` lies in ``(-nh, 2 nh)``, where
    ``x % nh`` is ``x - nh`` (exact) at or above ``nh``, ``x + nh`` below zero and ``x``
    between (what numpy's floating remainder computes there), without its division."""
    dh += nh / 2
    dh -= np.multiply(dh >= nh, nh, dtype=float)
    dh += np.multiply(dh < 0.0, nh, dtype=float)
    dh -= nh / 2
    return dh


def _join(dens: _Density, coords: np.ndarray, values: np.ndarray, valley: float,
          nh: int) -> np.ndarray:
    """Component of each mode: modes joined where the density between them holds up."""
    k = coords.shape[0]
    if k == 1:
        return np.zeros(1, dtype=np.int64)
    pairs = _PAIRS[1] < k  # the pairs of np.triu_indices(k, 1), in its order
    i, j = _PAIRS[0][pairs], _PAIRS[1][pairs]
    t = _LINE_STEPS[None, :, None]
    a, b = coords[i][:, None, :], coords[j][:, None, :]
    d = b - a
    _wrapped(d[..., 2], nh)  # in place: the modes' headings lie in (0, nh)
    pts = np.floor(a + t * d).astype(np.int64)
    # x and y lie between the two modes' cells, on the lattice: only the heading wraps
    line = dens.at(pts[..., 0], pts[..., 1], pts[..., 2] % nh)
    joined = np.minimum.reduce(line, axis=1) >= valley * np.minimum(values[i], values[j])
    return _components(k, i[joined].tolist(), j[joined].tolist())


def _components(k: int, first: list[int], second: list[int]) -> np.ndarray:
    """Connected components of the graph on ``k`` nodes with the edges ``first[e]`` -
    ``second[e]``, numbered in the order of each component's lowest node.

    Why not `scipy.sparse.csgraph`: the graph has at most ``MAX_PEAKS`` nodes, and
    importing scipy's sparse graphs cost every game's start more than all its
    clusterings' joins (0.04 CPU s).
    """
    root = list(range(k))  # each set's root is its lowest node

    def find(a: int) -> int:
        while root[a] != a:
            root[a] = a = root[root[a]]
        return a

    for a, b in zip(first, second, strict=True):
        ra, rb = find(a), find(b)
        if ra != rb:
            root[max(ra, rb)] = min(ra, rb)
    number: dict[int, int] = {}
    return np.array([number.setdefault(find(n), len(number)) for n in range(k)],
                    dtype=np.int64)


def _sorted_unique(values: np.ndarray, bound: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(values, return_inverse=True)`` for non-negative ints below ``bound``,
    by marking a table of ``bound`` cells instead of sorting (the lattice bounds every
    key here to a few ten thousand, and a sort of the particles' keys cost more)."""
    mark = np.zeros(bound, dtype=np.intp)
    mark[values] = 1
    unique = mark.nonzero()[0]
    mark[unique] = np.arange(unique.size)
    return unique, mark[values]


def _heading_pass(row: np.ndarray, h: np.ndarray, value: np.ndarray, lines: int,
                  nh: int) -> tuple[np.ndarray, np.ndarray]:
    """``gaussian_filter1d`` along the heading (wrapped) of the (lines, nh) array that
    holds ``value`` at ``(row, h)`` and zeros elsewhere, filtering only the headings
    where the result can be non-zero, and kept on those: ``(d, col)`` with ``d[:, col]``
    the filtered (lines, nh) array, ``col`` (nh,) each heading's column of ``d``.

    The particles' headings usually cover part of the circle, and every line carries
    weight at those headings only. The result is non-zero only within the filter's
    radius of them: the shortest arc holding every heading with weight, widened by the
    radius on both sides. That arc is filtered alone with zeros beyond its ends (mode
    ``constant``), one column of zeros after it: each of its cells sums the same products
    in the same order as on the whole line (what lies beyond the arc is zero on the line
    too), and every cell off the arc is exactly zero on the line as well, so every
    heading off the arc reads the zero column (``col``). Where the arc spans the circle
    the whole lines are filtered, wrapped, and ``col`` is the identity.
    """
    if h.size == 0:  # no weight: what the filter leaves of zeros
        return np.zeros((lines, 1)), np.zeros(nh, dtype=np.intp)
    used = np.zeros(nh, dtype=bool)
    used[h] = True
    cols = used.nonzero()[0]
    gaps = np.empty_like(cols)  # from each heading with weight to the next one
    gaps[:-1] = cols[1:] - cols[:-1]
    gaps[-1] = cols[0] + nh - cols[-1]
    widest = int(gaps.argmax())
    start = int(cols[(widest + 1) % cols.size]) - _RADIUS
    width = nh - int(gaps[widest]) + 1 + 2 * _RADIUS
    if width >= nh:
        d = np.zeros((lines, nh))
        d.reshape(-1)[row * nh + h] = value
        return _smooth(d, 1, _MODES[2]), np.arange(nh)
    col = np.full(nh, width, dtype=np.intp)  # off the arc: the zero column
    col[(start + np.arange(width)) % nh] = np.arange(width)
    d = np.zeros((lines, width + 1))
    d.reshape(-1)[row * (width + 1) + col[h]] = value
    return _smooth(d, 1, "constant"), col


class _Density:
    """The smoothed weight density on the lattice, stored by its lines that carry weight.

    The values are ``scipy.ndimage.gaussian_filter(mass, SMOOTH_CELLS, mode=_MODES)``
    of the (nx, ny, nh) lattice of summed weights, the same floats: that filter is one
    `gaussian_filter1d` along each axis in turn, each lattice line on its own, and a
    line without weight stays zero. So each pass filters only the lines that carry
    weight (the particles' lines along x, then the lines along y that the first pass
    reached, then those along the heading, on the arc of headings that can be
    non-zero: `_heading_pass`), with the same boundary modes.

    A density is read through a table of the (nx, ny) cells (at most
    ``MAX_LATTICE_CELLS / 72``) giving each cell's stored heading line, or a zero line
    kept after the stored ones, and a table of the headings giving each one's stored
    column, or a zero column: one gather per read, no search.

    Faint lines read as zeros: a heading line whose every input (what the second pass
    left on it) lies under ``_WEAK`` of the highest input is not filtered. Its density
    is under that share of the highest input too (the filter's weights are positive and
    sum to one), while the highest density is at least the kernel's centre weight (0.40)
    times the highest input, so a cell of such a line is under ``VALLEY`` times the
    peak floor: it is no peak, never exceeds a peak of its window, and on the line
    between two modes falls under ``VALLEY`` times the lower one whether read as its
    value or as zero. The highest density, the peaks and the joins are the whole
    density's; about three lines in five of a belief's clusterings are faint.

    Why: the lattice is bounded by the particles' extent (up to ``MAX_LATTICE_CELLS``),
    and a belief spread over a room holds a few hundred occupied cells in a million;
    filtering and scanning the whole lattice took tens of ms per clustering.

    Args:
        ix, iy, ih: each particle's lattice cell.
        w: each particle's weight (summed per cell in particle order, as ``np.add.at``).
        shape: (nx, ny, nh) of the lattice.
    """

    def __init__(self, ix: np.ndarray, iy: np.ndarray, ih: np.ndarray, w: np.ndarray,
                 shape: tuple[int, int, int]) -> None:
        nx, ny, nh = shape
        self.shape = shape
        # pass 1, along x: the lines (y, h) holding particles, as columns of (nx, n)
        yh, col = _sorted_unique(iy * nh + ih, ny * nh)
        ys, hs = np.divmod(yh, nh)
        a = np.zeros((nx, yh.size))
        np.add.at(a.reshape(-1), ix * yh.size + col, w)
        a = _smooth(a, 0, _MODES[0])
        # pass 2, along y: the lines (x, h) where pass 1 left a value, as rows of (n, ny)
        r, c = nonzero_2d(a)
        lines, row = _sorted_unique(r * nh + hs[c], nx * nh)
        b = np.zeros((lines.size, ny))
        b[row, ys[c]] = a[r, c]
        b = _smooth(b, 1, _MODES[1])
        xs, hs = np.divmod(lines, nh)
        # pass 3, along the heading: the lines (x, y) where pass 2 left a value, and after
        # them one line of zeros, where the table sends every cell without a line
        r, c = nonzero_2d(b)
        value = b[r, c]
        key = xs[r] * ny + c
        most = float(np.maximum.reduce(value)) if value.size else 0.0
        mark = np.zeros(nx * ny, dtype=bool)
        mark[key[value >= _WEAK * most] if most > _TINY else key] = True
        xy = mark.nonzero()[0]
        self._xy = xy
        """Flat (x, y) of the stored heading lines, ascending."""
        self._line = np.full(nx * ny, xy.size, dtype=np.intp)
        """Each (x, y) cell's line in ``_d`` (flat), the zero line where none is stored."""
        self._line[xy] = np.arange(xy.size)
        row = self._line[key]
        on = row < xy.size
        self._d, self._col = _heading_pass(row[on], hs[r][on], value[on], xy.size + 1, nh)
        """The density along each stored line, then the zero line: (lines + 1, columns);
        each heading's column (nh,)."""
        self.top = float(np.maximum.reduce(self._d, axis=None))
        """The highest density (0 when there is no weight)."""

    def at(self, x: np.ndarray, y: np.ndarray, h: np.ndarray) -> np.ndarray:
        """The density at lattice cells (on the lattice; any shape); 0 off the stored lines
        (on lines without weight, and on the faint ones)."""
        return self._d[self._line[x * self.shape[1] + y], self._col[h]]

    def peaks(self, floor: float) -> tuple[np.ndarray, np.ndarray]:
        """Local maxima with a positive density at or above ``floor``: their cells (K, 3)
        in row-major order and their densities, as ``dens == maximum_filter(dens,
        size=3, mode=_MODES)`` with ``dens >= floor`` and ``dens > 0`` selects them (a
        cell is a maximum when no cell of its 3 x 3 x 3 window, clamped at the edges in x
        and y and wrapped in the heading, is higher)."""
        nx, ny, nh = self.shape
        col = self._col
        head = np.empty(self._d.shape[1], dtype=np.intp)  # each stored column's heading
        head[col] = np.arange(nh)  # (the zero column's is any heading off the arc)
        stored = self._d[:-1]
        j, c = nonzero_2d(stored >= floor if floor > 0.0 else stored > 0.0)
        value = stored[j, c]
        h = head[c]
        # the window holds the cell's two heading neighbours on its own line: a cell below
        # either is no maximum, and is not looked up in the whole window
        up = h + 1
        up[up == nh] = 0
        down = h - 1
        down[down < 0] = nh - 1
        line = (value >= stored[j, col[up]]) & (value >= stored[j, col[down]])
        j, c, h, value = j[line], c[line], h[line], value[line]
        # nor below any of its four neighbours at the same heading: the same column of the
        # lines beside it (the cell itself at the lattice's edge, as the window is clamped)
        flat = self._xy[j]
        x, y = np.divmod(flat, ny)
        beside = np.stack([flat - ny * (x > 0), flat + ny * (x < nx - 1), flat - (y > 0),
                           flat + (y < ny - 1)])
        level = value >= np.maximum.reduce(self._d[self._line[beside], c], axis=0)
        x, y, h, value = x[level], y[level], h[level], value[level]
        # row-major order (stored lines ascend; an arc's columns may pass heading 0)
        order = ((x * ny + y) * nh + h).argsort()
        x, y, h, value = x[order], y[order], h[order], value[order]
        step = np.array([-1, 0, 1])
        wx = _clip(x[:, None] + step, nx - 1)[:, :, None, None]
        wy = _clip(y[:, None] + step, ny - 1)[:, None, :, None]
        wh = ((h[:, None] + step) % nh)[:, None, None, :]
        window = self.at(wx, wy, wh).reshape(x.size, -1)
        keep = value >= np.maximum.reduce(window, axis=1)
        return np.array([x, y, h]).T[keep], value[keep]
