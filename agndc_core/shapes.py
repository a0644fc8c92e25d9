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
    """Plain box (``segs`` unused: every body builder takes the same arguments)."""
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
    t = min(a, b) * rng.uniform(0.2, 0.45)  # arm thickness of the L and T
    if kind == 0:
        ang = np.linspace(0, 2 * np.pi, rng.choice([3, 5, 6, 8]), endpoint=False)
        poly = 0.5 * a * np.column_stack([np.cos(ang), np.sin(ang)])
    elif kind == 1:  # L, counter-clockwise (the positive fill rule drops clockwise contours)
        poly = np.array([[0, 0], [a, 0], [a, t], [t, t], [t, b], [0, b]])
    elif kind == 2:  # T: stem of width t, bar of thickness t on top
        poly = np.array([[-t / 2, 0], [t / 2, 0], [t / 2, b - t], [a / 2, b - t], [a / 2, b],
                         [-a / 2, b], [-a / 2, b - t], [-t / 2, b - t]])
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
    """Move the bounding-box centre to the origin."""
    lo, hi = _bounds(m)
    return m.translate(tuple(-(lo + hi) / 2))


def _bounds(m: Manifold) -> tuple[np.ndarray, np.ndarray]:
    """(3,) lower and (3,) upper corner of the bounding box."""
    b = np.asarray(m.bounding_box(), dtype=np.float64)
    return b[:3], b[3:]


# ---------------------------------------------------------------- features


def _face_frame(rng, lo, hi):
    """A random face of the box [lo, hi]: its axis, outward sign (+-1) and a point on it.

    The point stays in the middle 60 % of the face so features land on material even for
    round or slanted bodies whose bounding box is larger than the solid."""
    axis, sign = rng.integers(3), rng.choice([-1.0, 1.0])
    mid, half = (lo + hi) / 2, (hi - lo) / 2
    point = mid + rng.uniform(-0.3, 0.3, 3) * half
    point[axis] = mid[axis] + sign * half[axis]
    return axis, sign, point


def _along(m: Manifold, axis: int, sign: float) -> Manifold:
    """Turn a z-aligned tool (base at z=0, growing to +z) to grow along ``sign * axis``."""
    rot = {0: (0, 90, 0), 1: (-90, 0, 0), 2: (0, 0, 0)}[axis]
    m = m.rotate(rot)
    if sign < 0:
        m = m.mirror(tuple(np.eye(3)[axis]))
    return m


def _profile_tool(rng, segs, width: float, depth: float) -> Manifold:
    """z-aligned tool with base at z=0: round hole, square pocket, slot or countersink."""
    kind = rng.integers(4)
    r = width / 2
    if kind == 0:
        return Manifold.cylinder(depth, r, r, segs)
    if kind == 1:
        return Manifold.cube((width, width * rng.uniform(0.5, 1.5), depth)).translate((-r, -r, 0))
    if kind == 2:  # slot: hull of two holes
        d = width * rng.uniform(1.0, 2.5)
        pin = Manifold.cylinder(depth, r * 0.6, r * 0.6, segs)
        return Manifold.batch_hull([pin.translate((-d / 2, 0, 0)), pin.translate((d / 2, 0, 0))])
    return Manifold.cylinder(depth, r, r * rng.uniform(0.0, 0.5), segs)  # cone: countersink


def _cutter(rng, segs, lo, hi) -> Manifold:
    """A subtractive feature entering from a random face: through or blind, sometimes tilted."""
    axis, sign, point = _face_frame(rng, lo, hi)
    ext = hi - lo
    width = rng.uniform(0.1, 0.35) * np.delete(ext, axis).min()
    through = rng.random() < 0.5
    depth = ext[axis] * (1.2 if through else rng.uniform(0.2, 0.6))
    # the tool starts outside the face and points inwards
    tool = _profile_tool(rng, segs, width, depth + 0.05 * ext[axis])
    tool = tool.translate((0, 0, -0.05 * ext[axis]))
    if rng.random() < 0.25:  # an angled hole: off-axis crease inside an otherwise aligned part
        tool = tool.rotate(tuple(rng.uniform(-30, 30, 2)) + (rng.uniform(0, 90),))
    return _along(tool, axis, -sign).translate(tuple(point))


def _adder(rng, segs, lo, hi) -> Manifold:
    """An additive feature sunk into a random face: boss, rib or cone."""
    axis, sign, point = _face_frame(rng, lo, hi)
    ext = hi - lo
    lateral = np.delete(ext, axis).min()
    height = rng.uniform(0.15, 0.5) * max(ext.max(), 0.3)
    sink = 0.3 * ext[axis]  # overlap with the body so the feature is attached
    kind = rng.integers(3)
    if kind == 0:
        r = rng.uniform(0.15, 0.3) * lateral  # diameter >= ~2 voxels at 64^3
        tool = Manifold.cylinder(height + sink, r, r, segs)
    elif kind == 1:
        size = (rng.uniform(0.5, 1.0) * lateral, rng.uniform(0.08, 0.2) * lateral, height + sink)
        tool = Manifold.cube(size).translate((-size[0] / 2, -size[1] / 2, 0))
        tool = tool.rotate((0, 0, rng.uniform(0, 180)))
    else:
        r = rng.uniform(0.15, 0.35) * lateral
        tool = Manifold.cylinder(height + sink, r, r * rng.uniform(0, 0.5), segs)
    tool = tool.translate((0, 0, -sink))
    return _along(tool, axis, sign).translate(tuple(point))


# ---------------------------------------------------------------- assembly


def _part(rng, segs) -> Manifold:
    """A base body with 0-2 added and 0-3 subtracted features."""
    body = BODIES[rng.integers(len(BODIES))](rng, segs)
    lo, hi = _bounds(body)
    adds = [_adder(rng, segs, lo, hi) for _ in range(rng.integers(0, 3))]
    if adds:
        body = Manifold.batch_boolean([body, *adds], OpType.Add)
    lo, hi = _bounds(body)
    cuts = [_cutter(rng, segs, lo, hi) for _ in range(rng.integers(0, 4))]
    if cuts:
        body = Manifold.batch_boolean([body, *cuts], OpType.Subtract)
    return _centre(body)


def _assemble(rng, segs) -> Manifold:
    """One part, or 2-3 parts lined up with gaps along a random axis (disjoint components)."""
    n = rng.integers(2, 4) if rng.random() < MULTI_PART_FRACTION else 1
    parts, offset = [], 0.0
    axis = rng.integers(3)
    for _ in range(n):
        part = _part(rng, segs)
        lo, hi = _bounds(part)
        shift = np.zeros(3)
        shift[axis] = offset - lo[axis]
        parts.append(part.translate(tuple(shift)))
        offset += (hi - lo)[axis] + rng.uniform(0.08, 0.3)  # gap of several voxels at 64^3
    return Manifold.batch_boolean(parts, OpType.Add)


def _random_rotation(rng) -> np.ndarray:
    """(3, 3) rotation: uniform on SO(3), or a signed axis permutation (det +1)."""
    if rng.random() < AXIS_ALIGNED_FRACTION:
        m = np.eye(3)[rng.permutation(3)] * rng.choice([-1.0, 1.0], 3)
        if np.linalg.det(m) < 0:
            m[2] = -m[2]
        return m
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q * np.sign(np.diag(r))  # makes the QR factor Haar-uniform
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def _global_transform(m: Manifold, rng) -> Manifold:
    """Non-uniform stretch along the part axes, then a rotation."""
    affine = np.zeros((3, 4))
    affine[:, :3] = _random_rotation(rng) @ np.diag(rng.uniform(*STRETCH, 3))
    return m.transform(affine)


def _drop_slivers(m: Manifold) -> Manifold:
    """Remove components below ``MIN_COMPONENT_SHARE`` of the volume."""
    comps = m.decompose()
    if len(comps) < 2:
        return m
    vols = np.array([c.volume() for c in comps])
    keep = [c for c, v in zip(comps, vols) if v >= MIN_COMPONENT_SHARE * vols.sum()]
    return Manifold.batch_boolean(keep, OpType.Add)


def _to_arrays(m: Manifold) -> tuple[np.ndarray, np.ndarray]:
    """Normalised (V, 3) float64 vertices and (F, 3) int64 faces of a manifold."""
    mesh = m.to_mesh64()
    v = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3]
    f = np.asarray(mesh.tri_verts).astype(np.int64)
    lo, hi = v.min(axis=0), v.max(axis=0)
    return (v - (lo + hi) / 2) / (hi - lo).max(), f


def _attempt(seed: int, attempt: int) -> Manifold | None:
    """One draw of a shape; None when the booleans left nothing usable."""
    rng = np.random.default_rng((seed, attempt))
    segs = int(rng.integers(SEGMENTS[0], SEGMENTS[1] + 1))
    m = _global_transform(_assemble(rng, segs), rng)
    if m.is_empty() or m.status().name != "NoError" or m.volume() <= 0:
        return None
    m = _drop_slivers(m)
    lo, hi = _bounds(m)
    # reject needles and sheets: after normalisation some side would be sub-voxel
    return m if (hi - lo).min() > 0.05 * (hi - lo).max() else None


def generate_shape(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A watertight CAD-like solid, deterministic in ``seed``.

    Args:
        seed: non-negative integer.

    Returns:
        vertices: (V, 3) float64, bounding box centred at the origin, longest side 1.
        faces: (F, 3) int64, outward-oriented triangles of a closed 2-manifold.
    """
    for attempt in range(MAX_ATTEMPTS):
        m = _attempt(seed, attempt)
        if m is not None:
            return _to_arrays(m)
    return _to_arrays(Manifold.cube((1.0, 0.7, 0.5), center=True))  # never reached in practice


def generate_dataset(n: int, seed0: int = 0):
    """Yield ``(seed, vertices, faces)`` for seeds ``seed0 .. seed0 + n - 1``."""
    for seed in range(seed0, seed0 + n):
        yield (seed, *generate_shape(seed))
