"""The belief's clusters: modes joined into hypotheses, numbered like scipy's components."""

from __future__ import annotations

import math

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from actors.firmware.localisation.clusters import _components, cluster_labels


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
