"""Is a triangle mesh a closed, consistently oriented 2-manifold? Counts of each defect.

Used by the manifold property tests and by ``research/check_manifold.py`` (every dev mesh, every
method); vectorised, so a 128^3 reconstruction is checked in well under a second.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components


def topology_violations(vertices, faces) -> dict:
    """Counts of defects of a closed oriented 2-manifold triangle mesh (all 0 when it is one)."""
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    a, b, c = faces.T
    half = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)  # directed edges a->b, b->c, c->a
    _, undirected = np.unique(np.sort(half, axis=1), axis=0, return_counts=True)
    _, directed = np.unique(half, axis=0, return_counts=True)
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.reshape(-1)] = True
    fans = _fans_per_vertex(faces, len(vertices))
    return {
        "degenerate_faces": int(np.sum((a == b) | (b == c) | (a == c))),
        "edges_not_in_two_faces": int(np.sum(undirected != 2)),
        "edges_same_direction_twice": int(np.sum(directed != 1)),  # inconsistent orientation
        "vertices_not_one_fan": int(np.sum(fans[used] != 1)),
        "unused_vertices": int(np.sum(~used)),
    }


def _fans_per_vertex(faces, n_vertices) -> np.ndarray:
    """(V,) number of fans: cycles of the link (face (a, b, c) gives a the link edge b - c)."""
    centre = faces.T.reshape(-1)
    start = faces[:, [1, 2, 0]].T.reshape(-1)
    end = faces[:, [2, 0, 1]].T.reshape(-1)
    keys, inverse = np.unique(np.concatenate([centre * n_vertices + start,
                                              centre * n_vertices + end]), return_inverse=True)
    m = len(centre)
    graph = coo_matrix((np.ones(m), (inverse[:m], inverse[m:])), shape=(len(keys),) * 2)
    _, label = connected_components(graph, directed=False)
    owner = keys // n_vertices
    fan_keys = np.unique(owner * len(keys) + label)
    return np.bincount(fan_keys // len(keys), minlength=n_vertices)
