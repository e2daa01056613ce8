"""The belief's clusters: the density and its modes equal scipy's filters on the whole
lattice; modes joined into hypotheses, numbered like scipy's connected components."""

from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import gaussian_filter, gaussian_filter1d, maximum_filter
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from actors.firmware.localisation.clusters import (
    CELL_CM,
    MAX_LATTICE_CELLS,
    MAX_PEAKS,
    PEAK_FLOOR,
    SMOOTH_CELLS,
    VALLEY,
    _components,
    _Density,
    _heading_pass,
    _join,
    _wrapped,
    cluster_labels,
)


def test_joined_modes_are_numbered_as_scipy_numbers_connected_components() -> None:
    rng = np.random.default_rng(7)
    for _ in range(500):
        k = int(rng.integers(2, 33))
        m = int(rng.integers(0, 50))
        i, j = rng.integers(0, k, m), rng.integers(0, k, m)
        _, want = connected_components(coo_matrix((np.ones(m), (i, j)), shape=(k, k)),
                                       directed=False)
        assert _components(k, i.tolist(), j.tolist()).tolist() == want.tolist()


def test_two_groups_far_apart_are_two_hypotheses() -> None:
    rng = np.random.default_rng(3)
    a = np.column_stack([rng.normal(0, 2, 200), rng.normal(0, 2, 200),
                         np.full(200, 0.1)])
    b = np.column_stack([rng.normal(80, 2, 200), rng.normal(0, 2, 200),
                         np.full(200, 0.1 + math.pi / 2)])
    labels = cluster_labels(np.vstack([a, b]), np.ones(400))
    assert set(labels[:200].tolist()) == {labels[0]}
    assert set(labels[200:].tolist()) == {labels[200]}
    assert labels[0] != labels[200]


def _dense_modes(particles: np.ndarray, weights: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The density, its peaks and their values computed on the whole lattice with
    scipy's filters (what `_Density` must equal), and the lattice cells."""
    nh, pad = 72, 4
    p = particles
    x0, y0 = float(p[:, 0].min()), float(p[:, 1].min())
    span = max(float(p[:, 0].max()) - x0, float(p[:, 1].max()) - y0)
    cell = max(CELL_CM, span / max(math.sqrt(MAX_LATTICE_CELLS / nh) - 2 * pad, 1.0))
    ix = ((p[:, 0] - x0) / cell + pad).astype(np.int64)
    iy = ((p[:, 1] - y0) / cell + pad).astype(np.int64)
    ih = ((np.degrees(p[:, 2]) % 360.0) / (360.0 / nh)).astype(np.int64) % nh
    mass = np.zeros((int(ix.max()) + pad + 1, int(iy.max()) + pad + 1, nh))
    np.add.at(mass, (ix, iy, ih), weights)
    dens = gaussian_filter(mass, SMOOTH_CELLS, mode=("nearest", "nearest", "wrap"))
    peak = (dens == maximum_filter(dens, size=3, mode=("nearest", "nearest", "wrap"))) \
        & (dens >= PEAK_FLOOR * dens.max())
    return dens, np.argwhere(peak), dens[peak], np.stack([ix, iy, ih])


def test_the_density_and_its_peaks_equal_scipys_filters_on_the_whole_lattice() -> None:
    rng = np.random.default_rng(11)
    for trial in range(20):
        groups = int(rng.integers(1, 5))
        n = int(rng.integers(1, 400))
        centres = rng.uniform(-300, 300, (groups, 2))
        pick = rng.integers(0, groups, n)
        spread = rng.uniform(0.5, 40.0)
        xy = centres[pick] + rng.normal(0, spread, (n, 2))
        theta = rng.choice([0.0, math.pi - 1e-9, -math.pi + 0.01, 1.0], n) \
            + rng.normal(0, 0.2, n)
        p = np.column_stack([xy, theta])
        w = rng.random(n) if trial % 3 else np.ones(n)
        dens, coords, values, (ix, iy, ih) = _dense_modes(p, w)
        d = _Density(ix, iy, ih, w, dens.shape)
        assert d.top == float(dens.max())
        read = d.at(*np.indices(dens.shape))
        stored = read != 0.0  # every other cell is faint: under what a join compares with
        assert np.array_equal(read[stored], dens[stored])
        assert float(dens[~stored].max(initial=0.0)) < VALLEY * PEAK_FLOOR * d.top
        got, got_values = d.peaks(PEAK_FLOOR * d.top)
        assert np.array_equal(got, coords) and np.array_equal(got_values, values)


class _Dense:
    """The whole lattice's density, read as `_Density` is (for `_join`)."""

    def __init__(self, dens: np.ndarray) -> None:
        self.dens, self.shape = dens, dens.shape

    def at(self, x: np.ndarray, y: np.ndarray, h: np.ndarray) -> np.ndarray:
        return self.dens[x, y, h]


def _dense_labels(particles: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """`cluster_labels` computed on the whole lattice's density (scipy's filters)."""
    dens, coords, values, _ = _dense_modes(particles, weights)
    nh = dens.shape[2]
    order = (-values).argsort(kind="stable")[:MAX_PEAKS]
    coords, values = coords[order].astype(float) + 0.5, values[order]
    comp = _join(_Dense(dens), coords, values, VALLEY, nh)
    p = particles
    x0, y0 = float(p[:, 0].min()), float(p[:, 1].min())
    span = max(float(p[:, 0].max()) - x0, float(p[:, 1].max()) - y0)
    cell = max(CELL_CM, span / max(math.sqrt(MAX_LATTICE_CELLS / nh) - 8, 1.0))
    gx, gy = (p[:, 0] - x0) / cell + 4, (p[:, 1] - y0) / cell + 4
    gh = (np.degrees(p[:, 2]) % 360.0) / (360.0 / nh)
    dh = (gh[:, None] - coords[None, :, 2] + nh / 2) % nh - nh / 2
    d2 = (gx[:, None] - coords[None, :, 0]) ** 2 + (gy[:, None] - coords[None, :, 1]) ** 2 \
        + dh * dh
    return comp[np.argmin(d2, axis=1)]


def test_the_labels_are_those_of_the_whole_lattices_density() -> None:
    """Faint lines read as zeros, one hypothesis labelled without the search, the
    heading wrapped without a remainder: the labels of the whole density, for groups
    near and far, joined and apart, across heading 0."""
    rng = np.random.default_rng(23)
    several = 0
    for _ in range(40):
        groups = int(rng.integers(1, 5))
        n = int(rng.integers(20, 500))
        centres = rng.uniform(-40, 40, (groups, 2))
        heads = rng.uniform(-math.pi, math.pi, groups)
        pick = rng.integers(0, groups, n)
        xy = centres[pick] + rng.normal(0, rng.uniform(1.0, 8.0), (n, 2))
        theta = (heads[pick] + rng.normal(0, 0.15, n) + math.pi) % (2 * math.pi) - math.pi
        p = np.column_stack([xy, theta])
        w = rng.random(n) ** 3
        labels = cluster_labels(p, w)
        assert np.array_equal(labels, _dense_labels(p, w))
        several += int(labels.max()) > 0
    assert several >= 10  # most draws hold several hypotheses


def test_a_zero_floor_finds_every_positive_peak() -> None:
    rng = np.random.default_rng(2)
    p = np.column_stack([rng.normal(0, 3, 30), rng.normal(0, 3, 30),
                         rng.normal(3.0, 0.1, 30)])
    w = rng.random(30)
    dens, _, _, (ix, iy, ih) = _dense_modes(p, w)
    d = _Density(ix, iy, ih, w, dens.shape)
    peak = (dens == maximum_filter(dens, size=3, mode=("nearest", "nearest", "wrap"))) \
        & (dens > 0)
    got, got_values = d.peaks(0.0)
    assert np.array_equal(got, np.argwhere(peak)) and np.array_equal(got_values, dens[peak])


def test_the_wrapped_heading_difference_is_numpys_remainder() -> None:
    rng = np.random.default_rng(4)
    nh = 72
    gh = np.concatenate([rng.uniform(0, nh, 4000), [0.0, 36.0, 71.5, 72.0 - 1e-12, 35.5]])
    modes = np.concatenate([rng.integers(0, nh, 30) + 0.5, [0.5, 71.5, 36.5]])
    dh = np.subtract.outer(gh, modes)
    want = (dh + nh / 2) % nh - nh / 2
    assert np.array_equal(_wrapped(dh.copy(), nh), want)


def test_particles_without_weight_are_one_hypothesis() -> None:
    p = np.array([[0.0, 0.0, 0.0], [100.0, 0.0, 1.0]])
    assert cluster_labels(p, np.zeros(2)).tolist() == [0, 0]
    assert cluster_labels(p[:1], np.ones(1)).tolist() == [0]


def test_the_heading_pass_equals_the_wrapped_filter_of_whole_lines() -> None:
    """Filtering only the arc of headings that can carry density gives the floats of
    the whole wrapped lines, read through the heading table: arcs across heading 0,
    inside the circle, a single heading, arcs just short of and over the whole circle."""
    rng = np.random.default_rng(5)
    nh = 72
    for first, span in [(70, 5), (0, 0), (30, 12), (66, 40), (10, 54), (3, 62), (3, 63), (5, 71)]:
        lines = int(rng.integers(1, 40))
        n = int(rng.integers(1, 200))
        row = rng.integers(0, lines, n)
        h = (first + rng.integers(0, span + 1, n)) % nh
        h[0] = first  # both ends of the arc carry weight
        h[-1] = (first + span) % nh
        value = rng.random(n)
        whole = np.zeros((lines, nh))
        whole[row, h] = value
        want = gaussian_filter1d(whole, SMOOTH_CELLS, axis=1, mode="wrap")
        d, col = _heading_pass(row, h, value, lines, nh)
        assert np.array_equal(d[:, col], want)
        assert d.shape[1] <= nh + 1
