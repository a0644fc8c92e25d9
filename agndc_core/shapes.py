"""Seeded procedural CAD-like solids for training data (manifold3d booleans).

A shape is one to three *parts*. A part is a base body (box, cylinder/frustum, extruded
polygon or wedge, chamfered block, shelled box or tube) with a few added features (bosses,
ribs, cones) and subtracted ones (through-holes, blind pockets, slots, countersinks, angled
holes). The whole shape then gets a random non-uniform scale and a rotation: a random 3-D
rotation for most seeds, a signed axis permutation for ``AXIS_ALIGNED_FRACTION`` of them, so
the set holds both grid-aligned and off-grid creases. The output is normalised (bounding-box
centre at the origin, longest side 1), the frame the metrics and the voxeliser use.

Everything is drawn from ``np.random.default_rng((seed, attempt))``, so a seed always gives
the same arrays; an attempt whose booleans leave nothing usable is retried with the next
``attempt`` (a derived seed). manifold3d guarantees a watertight, oriented 2-manifold result.

Sizes below are in the nominal units of a part before normalisation (a part is ~1 across).
"""

from __future__ import annotations

import numpy as np
from manifold3d import CrossSection, Manifold, OpType

#: range of circle segments: enough that a hole looks round at 64^3 (a 64-gon deviates from
#: its circle by 0.1 % of the radius), few enough to keep meshes small
SEGMENTS = (24, 64)
#: share of shapes left on the grid axes (signed axis permutation instead of a free rotation)
AXIS_ALIGNED_FRACTION = 0.2
#: share of shapes made of several disjoint parts
MULTI_PART_FRACTION = 0.25
#: per-axis factor range of the global non-uniform scale
STRETCH = (0.6, 1.4)
#: edge-length range of a base body, nominal units
BODY_SIZE = (0.35, 1.0)
#: wall thickness of shelled bodies as a fraction of the body's smallest side (>= ~2 voxels
#: at 64^3 for typical bodies, so the walls survive voxelisation)
WALL_FRACTION = (0.12, 0.25)
#: connected components smaller than this share of the total volume are dropped (booleans
#: can leave slivers that are sub-voxel after normalisation)
MIN_COMPONENT_SHARE = 0.02
#: attempts (derived seeds) before falling back to a plain box
MAX_ATTEMPTS = 16


# ---------------------------------------------------------------- base bodies


def _box(rng, segs) -> Manifold:
    return Manifold.cube(rng.uniform(*BODY_SIZE, 3), center=True)


def _cylinder(rng, segs) -> Manifold:
    """Cylinder, or a frustum/cone for a third of the draws, along z."""
    h, r = rng.uniform(*BODY_SIZE), rng.uniform(0.15, 0.5)
    top = r * rng.uniform(0.0, 0.8) if rng.random() < 0.33 else r
    return Manifold.cylinder(h, r, top, segs, center=True)


def _prism(rng, segs) -> Manifold:
    """Extruded profile: regular polygon, L, T, or right-triangle wedge."""
    kind = rng.integers(4)
    a, b = rng.uniform(*BODY_SIZE, 2)
    if kind == 0:
        ang = np.linspace(0, 2 * np.pi, rng.choice([3, 5, 6, 8]), endpoint=False)
        poly = 0.5 * a * np.column_stack([np.cos(ang), np.sin(ang)])
    elif kind == 1:  # L: a bar of width t along x and y
        t = a * rng.uniform(0.25, 0.5)
        poly = np.array([[0, 0], [a, 0], [a, t], [t, t], [t, b], [0, b]])
    elif kind == 2:  # T
        t = a * rng.uniform(0.2, 0.4)
        poly = np.array([[-a / 2, b - t], [a / 2, b - t], [a / 2, b], [-a / 2, b],
                         [-a / 2, b - t], [-t / 2, b - t], [-t / 2, 0], [t / 2, 0],
                         [t / 2, b - t]])[[0, 5, 6, 7, 8, 1, 2, 3]]
    else:  # wedge
        poly = np.array([[0, 0], [a, 0], [0, b]])
    h = rng.uniform(*BODY_SIZE)
    body = CrossSection([poly]).extrude(h)
    return _centre(body)


def _chamfered_block(rng, segs) -> Manifold:
    """Box with 45-degree chamfers on a random subset of its 12 edges."""
    size = rng.uniform(*BODY_SIZE, 3)
    body = Manifold.cube(size, center=True)
    cutters = []
    for _ in range(rng.integers(2, 7)):
        axis = rng.integers(3)
        other = [i for i in range(3) if i != axis]
        c = rng.uniform(0.1, 0.3) * size[other].min()
        # a square bar rotated 45 degrees about the edge removes a right triangle of legs c
        bar = np.full(3, c * np.sqrt(2))
        bar[axis] = size[axis] * 1.5
        rot = np.zeros(3)
        rot[axis] = 45.0
        pos = np.zeros(3)
        pos[other] = rng.choice([-0.5, 0.5], 2) * size[other]
        cutters.append(Manifold.cube(bar, center=True).rotate(rot).translate(pos))
    return body - Manifold.batch_boolean(cutters, OpType.Add)


def _shell(rng, segs) -> Manifold:
    """Thin-walled box: an open tray, or a tube open at both ends (genus 1)."""
    size = rng.uniform(*BODY_SIZE, 3)
    t = rng.uniform(*WALL_FRACTION) * size.min()
    inner = size - 2 * t
    tube = rng.random() < 0.4
    inner[2] = size[2] * 2 if tube else size[2]
    shift = 0.0 if tube else t  # the tray keeps its floor
    cavity = Manifold.cube(inner, center=True).translate((0, 0, shift))
    return Manifold.cube(size, center=True) - cavity


BODIES = (_box, _cylinder, _prism, _chamfered_block, _shell)


def _centre(m: Manifold) -> Manifold:
    lo, hi = _bounds(m)
    return m.translate(tuple(-(lo + hi) / 2))


def _bounds(m: Manifold) -> tuple[np.ndarray, np.ndarray]:
    """(3,) lower and (3,) upper corner of the bounding box."""
    b = np.asarray(m.bounding_box(), dtype=np.float64)
    return b[:3], b[3:]
