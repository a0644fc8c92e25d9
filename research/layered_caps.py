"""Shallow parts built of layers about one voxel thick at 64³ (caps, lids, knobs): whether
the networks lose to marching cubes on such parts in general, as AGNDC does on the dev mesh
``abc8``, a cap whose rim, recessed floor, slot and inner shelf are each 1.03 voxels apart.

    .venv/bin/python research/layered_caps.py -o runs/caps -n 24
    .venv/bin/agndc eval runs/caps -o out/caps --res 64 --samples 30000 \
        --methods mc,undc,agndc,agndc_fast,oracle_binary

Each shape (deterministic in its seed, a stream of its own): a layer height of ``--layer``
voxels (default 0.85-1.3); a skirt 2-4 layers tall and 1 across; a body 6-10 layers tall and
0.8-0.95 across on it; a recess one layer deep in its top inside a rim 1-3 voxels wide, often
with a slot one more layer down across it and sometimes a boss one layer high in its middle;
half of the shapes hollow from below up to a shelf 1-2 layers thick. A round or a rounded
square outline; half of the shapes upside down (the recess faces down). Every third shape
turned by Euler angles along a random direction, 3-12° in all. Written as OBJ files with a
``MANIFEST.csv`` (kind ``cad``) that ``agndc eval`` reads.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from spike_rows import turned_arrays, write_set

#: the seed stream of these shapes (apart from the training generator's and the families')
SEED_STREAM = 1031
#: one voxel at 64³, in units of the longest side (the voxeliser spans it with 62)
VOXEL = 1.0 / 62


def _outline(round_shape: bool, radius: float, height: float, segs: int):
    """A vertical prism from z = 0 to ``height``: a disc or a rounded square of ``radius``."""
    from manifold3d import CrossSection, Manifold

    if round_shape:
        return Manifold.cylinder(height, radius, radius, segs)
    side = 2 * radius
    square = CrossSection.square((side, side), center=True)
    return square.offset(-0.2 * radius).offset(0.2 * radius, circular_segments=segs).extrude(height)


def layered_cap(seed: int, layer=(0.85, 1.3)) -> tuple[np.ndarray, np.ndarray]:
    """(V, 3) vertices (bounding box centred, longest side 1), (F, 3) faces of one shape; the
    layer height drawn from ``layer`` (voxels at 64³)."""
    from manifold3d import Manifold, OpType

    rng = np.random.default_rng((seed, SEED_STREAM))
    u = rng.uniform(*layer) * VOXEL
    segs = int(rng.integers(48, 97))
    round_shape = rng.random() < 0.6
    skirt_h = int(rng.integers(2, 5)) * u
    body_h = int(rng.integers(6, 11)) * u
    body_r = 0.5 * rng.uniform(0.8, 0.95)
    rim = rng.uniform(1, 3) * VOXEL
    shape = _outline(round_shape, 0.5, skirt_h, segs) + _outline(round_shape, body_r, body_h, segs)
    top = body_h
    recess_r = body_r - rim
    cuts = [_outline(round_shape, recess_r, 2 * u, segs).translate((0, 0, top - u))]
    if rng.random() < 0.7:  # a slot one more layer down across the floor
        width = rng.uniform(1.5, 4) * VOXEL
        length = 2 * recess_r * rng.uniform(0.5, 0.9)
        slot = Manifold.cube((length, width, 2 * u), center=True).rotate(
            (0, 0, rng.uniform(0, 180)))
        cuts.append(slot.translate((0, 0, top - u)))
    if rng.random() < 0.5:  # hollow from below up to a shelf 1-2 layers thick
        shelf = int(rng.integers(1, 3)) * u
        hollow_r = recess_r * rng.uniform(0.6, 0.9)
        cuts.append(_outline(round_shape, hollow_r, top - shelf, segs).translate(
            (0, 0, -u)))
    shape = shape - Manifold.batch_boolean(cuts, OpType.Add)
    if rng.random() < 0.4:  # a boss one layer high in the middle of the floor
        boss_r = recess_r * rng.uniform(0.15, 0.4)
        shape = shape + Manifold.cylinder(u, boss_r, boss_r, segs).translate((0, 0, top - u))
    if rng.random() < 0.5:  # upside down: the recess faces down
        shape = shape.mirror((0, 0, 1))
    return turned_arrays(shape, rng, seed)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--out", type=Path, required=True)
    parser.add_argument("-n", type=int, default=24)
    parser.add_argument("--layer", default="0.85,1.3", help="LO,HI layer height, voxels at 64³")
    args = parser.parse_args()

    layer = tuple(float(r) for r in args.layer.split(","))
    write_set(args.out, args.n, "cap", "cad", "layered_cap", lambda seed: layered_cap(seed, layer))


if __name__ == "__main__":
    main()
