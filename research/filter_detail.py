"""The normal filter, then part of its correction given back where it looks like detail.

The bilateral normal filter removes the network's cell-to-cell noise, and with it sub-voxel
detail a few cells long (the validation family's wrinkled figurines lose 5-16 % CD to it). This
study scores ``agndc eval`` with ``normalfilter.filter_mesh`` replaced by the filter followed by
one of three restorations, on vertices away from the filtered mesh's creases (a vertex whose
faces' normals spread more than ``--crease`` degrees from their mean, and the ring around it,
keep the filter's result; so do pinned coordinates). With ``r = filtered - network``:

* **low-pass** (default): ``filtered - alpha * P^k r``, with P the average over a vertex and
  its one-ring, k = ``--rings``: noise independent from vertex to vertex averages out, detail
  spanning several cells survives the average and is given back;
* ``--shrink TAU``: the same with the low-passed correction shrunk by TAU voxels (soft
  threshold on its length), so that the noise left after averaging is not given back;
* ``--gate A B``: ``filtered - w r`` with w rising from 0 to 1 as the RMS of the correction over
  three rings rises from A to B voxels (``--gate-low`` gives back ``w P^k r`` instead): where the
  filter moves a whole region by more than the noise, it is smoothing the network's detail.

    .venv/bin/python research/filter_detail.py DATA --res 64 --rings 1 -o OUT
    .venv/bin/python research/filter_detail.py DATA --res 64 --gate 0.05 0.08 -o OUT

docs/experiments/normal-filter.md ("Giving detail back") has the measurements.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from stage_eval import eval_parser, run_eval


def ring_average(faces: np.ndarray, n_vertices: int) -> sp.csr_matrix:
    """(V, V) row-stochastic matrix: the mean over a vertex and its edge neighbours."""
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    linked = sp.csr_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])),
                           shape=(n_vertices, n_vertices))
    linked = ((linked + linked.T) > 0).astype(np.float64) + sp.identity(n_vertices, format="csr")
    return sp.diags(1.0 / np.asarray(linked.sum(axis=1)).ravel()) @ linked


def away_from_creases(vertices, faces, average, crease_degrees: float) -> np.ndarray:
    """(V,) bool: vertices whose faces' normals all lie within ``crease_degrees`` of their
    mean (``normalfilter.normal_spread``), and whose ring holds no vertex that fails this."""
    from agndc_core.normalfilter import face_geometry, normal_spread, vertex_faces

    normals = face_geometry(vertices, faces)[0]  # (F, 3)
    spread = normal_spread(faces, vertex_faces(faces, len(vertices)), normals)
    crease = spread > crease_degrees
    return (average @ crease.astype(np.float64)) == 0


def give_detail_back(network, filtered, faces, fixed, args) -> np.ndarray:
    """The restoration chosen by ``args`` (module docstring) of a filtered mesh."""
    average = ring_average(faces, len(network))
    free = away_from_creases(filtered, faces, average, args.crease)
    correction = filtered - network  # (V, 3)
    low = correction
    for _ in range(args.rings):
        low = average @ low
    if args.shrink > 0:
        length = np.linalg.norm(low, axis=1, keepdims=True)
        low = low * np.maximum(1.0 - args.shrink / np.maximum(length, 1e-12), 0.0)
    if args.gate is None:
        weight, given = np.full(len(network), args.alpha), low
    else:
        a, b = args.gate
        squared = np.where(free, np.einsum("ij,ij->i", correction, correction), 0.0)
        counted = free.astype(np.float64)
        for _ in range(3):
            squared, counted = average @ squared, average @ counted
        rms = np.sqrt(squared / np.maximum(counted, 1e-12))
        weight, given = np.clip((rms - a) / (b - a), 0.0, 1.0), (low if args.gate_low
                                                                 else correction)
    restored = filtered - np.where(free, weight, 0.0)[:, None] * given
    return restored if fixed is None else np.where(fixed, filtered, restored)


def main() -> None:
    parser = eval_parser(__doc__, methods=False)
    parser.add_argument("--rings", type=int, default=1)
    parser.add_argument("--alpha", type=float, default=1.0)
    parser.add_argument("--crease", type=float, default=30.0, help="degrees")
    parser.add_argument("--shrink", type=float, default=0.0, help="voxels")
    parser.add_argument("--gate", type=float, nargs=2, default=None, metavar=("A", "B"))
    parser.add_argument("--gate-low", action="store_true")
    args = parser.parse_args()

    from agndc_core import normalfilter

    plain = normalfilter.filter_mesh

    def filter_and_restore(vertices, faces, params=normalfilter.DEFAULT, fixed_vx3=None,
                           check=None, planar_v=None):
        network = np.asarray(vertices, dtype=np.float64)
        faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
        filtered = plain(network, faces, params, fixed_vx3, check, planar_v)
        if len(faces) == 0:
            return filtered
        return give_detail_back(network, filtered, faces, fixed_vx3, args)

    # the pipeline imports filter_mesh when it runs the stage, so it finds this one
    normalfilter.filter_mesh = filter_and_restore
    run_eval(args)


if __name__ == "__main__":
    main()
