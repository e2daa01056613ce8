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
    1. The weights are summed on a lattice of ``cell_cm`` x ``cell_cm`` x
       ``cell_deg`` (heading periodic) and smoothed with a Gaussian of
       ``smooth_cells`` lattice cells (``scipy.ndimage.gaussian_filter``).
    2. Local maxima of the smoothed density (``maximum_filter`` over the 26
       neighbours) above ``peak_floor`` of the highest are the candidate modes
       (at most ``max_peaks``, highest first).
    3. Two modes are one hypothesis when the density along the straight line
       between them never falls under ``valley`` times the lower of the two
       (a plateau, or a ridge); the joined modes are the connected components
       of that relation (``scipy.sparse.csgraph.connected_components``).
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
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter, maximum_filter
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

__all__ = ["ClusterOptions", "cluster_labels"]


@dataclass(frozen=True, slots=True)
class ClusterOptions:
    """Parameters of the mode clustering."""

    cell_cm: float = 4.0
    """Position side of the lattice [cm]."""
    cell_deg: float = 5.0
    """Heading side of the lattice [deg]."""
    smooth_cells: float = 1.0
    """Standard deviation of the smoothing, in lattice cells [1]."""
    peak_floor: float = 0.05
    """Modes lower than this share of the highest are not modes [1]."""
    valley: float = 0.5
    """Two modes are one hypothesis unless the density between them dips under this share
    of the lower mode [1]."""
    max_peaks: int = 32
    """At most this many modes are considered, highest first [1]."""
    max_lattice_cells: int = 2_000_000
    """Bound on the lattice: a belief spread wider than this allows is clustered on a
    coarser position lattice [cells]."""

    def __post_init__(self) -> None:
        if not (self.cell_cm > 0 and 0 < self.cell_deg <= 90 and self.smooth_cells >= 0):
            raise ValueError("ClusterOptions needs cell_cm > 0, cell_deg in (0, 90] and "
                             f"smooth_cells >= 0, got {self.cell_cm!r}, {self.cell_deg!r}, "
                             f"{self.smooth_cells!r}")
        if not (0 <= self.peak_floor < 1 and 0 < self.valley <= 1 and self.max_peaks >= 1
                and self.max_lattice_cells >= 1000):
            raise ValueError("ClusterOptions needs peak_floor in [0, 1), valley in (0, 1], "
                             "max_peaks >= 1 and max_lattice_cells >= 1000")


_MODES = ("nearest", "nearest", "wrap")  # the heading axis is periodic
_LINE_SAMPLES = 16


def cluster_labels(particles: np.ndarray, weights: np.ndarray,
                   options: ClusterOptions | None = None) -> np.ndarray:
    """The hypothesis of every particle: labels (N,) in 0..K-1, K the hypotheses found.

    Args:
        particles: (N, 3) ``x``, ``y`` [cm], ``theta`` [rad].
        weights: (N,) non-negative weights.
        options: the clustering's parameters.
    """
    o = options or ClusterOptions()
    p = np.asarray(particles, dtype=float)
    w = np.asarray(weights, dtype=float)
    nh = max(1, round(360.0 / o.cell_deg))
    pad = math.ceil(3 * o.smooth_cells) + 1
    x0, y0 = float(p[:, 0].min()), float(p[:, 1].min())
    span = max(float(p[:, 0].max()) - x0, float(p[:, 1].max()) - y0)
    cell = max(o.cell_cm, span / max(math.sqrt(o.max_lattice_cells / nh) - 2 * pad, 1.0))
    gx = (p[:, 0] - x0) / cell + pad  # lattice coordinates [cells]
    gy = (p[:, 1] - y0) / cell + pad
    gh = (np.degrees(p[:, 2]) % 360.0) / (360.0 / nh)
    ix, iy = gx.astype(np.int64), gy.astype(np.int64)
    ih = gh.astype(np.int64) % nh
    mass = np.zeros((int(ix.max()) + pad + 1, int(iy.max()) + pad + 1, nh))
    np.add.at(mass, (ix, iy, ih), w)
    dens = gaussian_filter(mass, o.smooth_cells, mode=_MODES) if o.smooth_cells > 0 else mass
    top = float(dens.max())
    if top <= 0.0:
        return np.zeros(p.shape[0], dtype=np.int64)
    peak = (dens == maximum_filter(dens, size=3, mode=_MODES)) & (dens >= o.peak_floor * top)
    coords = np.argwhere(peak)
    values = dens[peak]
    order = np.argsort(-values, kind="stable")[:o.max_peaks]
    coords, values = coords[order].astype(float) + 0.5, values[order]
    comp = _join(dens, coords, values, o.valley, nh)
    # nearest mode of each particle, heading wrapped [cells]
    dx = gx[:, None] - coords[None, :, 0]
    dy = gy[:, None] - coords[None, :, 1]
    dh = (gh[:, None] - coords[None, :, 2] + nh / 2) % nh - nh / 2
    nearest = np.argmin(dx * dx + dy * dy + dh * dh, axis=1)
    return comp[nearest]


def _join(dens: np.ndarray, coords: np.ndarray, values: np.ndarray, valley: float,
          nh: int) -> np.ndarray:
    """Component of each mode: modes joined where the density between them holds up."""
    k = coords.shape[0]
    if k == 1:
        return np.zeros(1, dtype=np.int64)
    i, j = np.triu_indices(k, 1)
    t = np.linspace(0.0, 1.0, _LINE_SAMPLES)[None, :, None]
    a, b = coords[i][:, None, :], coords[j][:, None, :]
    d = b - a
    d[..., 2] = (d[..., 2] + nh / 2) % nh - nh / 2
    pts = np.floor(a + t * d).astype(np.int64)
    nx, ny, _ = dens.shape
    line = dens[np.clip(pts[..., 0], 0, nx - 1), np.clip(pts[..., 1], 0, ny - 1),
                pts[..., 2] % nh]
    joined = line.min(axis=1) >= valley * np.minimum(values[i], values[j])
    graph = coo_matrix((np.ones(int(joined.sum())), (i[joined], j[joined])), shape=(k, k))
    _, comp = connected_components(graph, directed=False)
    return comp.astype(np.int64)
