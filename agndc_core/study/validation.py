"""The validation family: generated shapes for choosing checkpoints, recipes and thresholds.

Model selection needs shapes the training never saw *and* that are not simply more draws of
the training generator: a network tuned on its own distribution looks better there than on the
meshes users bring. So this family has its own seed stream, its own classes and builders, and
kinds the training generator (``shapes.py``) lacks. Its three classes are the three kinds of
real meshes the remesher is judged on:

- ``cad`` (machined parts): the training generator's parts turned 1-15° off the grid axes (the
  slightly tilted faces that come out wavy; training has only aligned or uniformly random
  turns), flanges with bolt circles, spur gears with a keyed bore, thin bent brackets with holes
  and a gusset.
- ``organic``: figurines blended from ellipsoids and capsules with a smooth minimum (training
  blobs are metaball sums), half of them wrinkled like a scan (waves 3-10 voxels long), and
  knotted tubes.
- ``print`` (3-D-printing models): thin-walled vases and cups, low-poly faceted sculptures
  (flat faces at every angle, sharp creases), hexagonal lattice panels, name plates with
  raised pixel glyphs, stepped pyramids.

**Thin sheets** are a family of their own (``validation_sheet``, ``agndc val-data --sheets``, seeds
from ``SHEET_SEED0``): flat plates 1.5-3 voxels thick at 64^3, with holes, slots, windows and
pockets (gaskets, laser-cut and sheet-metal parts, plates lying on a print bed). Both the
training generator and the family above reject a shape whose shortest side is under 5 % of its
longest (3.1 voxels at 64^3), so a whole shape this thin is new to the networks; the two faces
that bound it lie in the shape's outermost layers of cells, where the flat-patch stage reads
their depth from the network (``flatpatches.py``; along a plate's longest side, where the
voxeliser puts them mid-layer, they go there).

**Thin struts** are a third family (``validation_strut``, ``agndc val-data --struts``, seeds
from ``STRUT_SEED0``): stools, lattice cubes, masts, coil springs and plates of pins, their bars
0.8-3 voxels in radius at 64^3 (columns of printed miniatures, lattices, wires), builders apart
from the training generator's strut frames (``shapes.strut_shape``).

``validation_shape(seed)`` returns the class, the builder's name and a normalised closed mesh
(bounding-box centre at the origin, longest side 1), deterministic in the seed. ``write_family``
writes OBJ files and a ``MANIFEST.csv`` whose ``kind`` column ``agndc eval`` reports by.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
from manifold3d import CrossSection, Manifold, OpType

from .shapes import (
    MAX_ATTEMPTS,
    _assemble,
    _bounds,
    _drop_slivers,
    _edge_manifold,
    _random_rotation,
    _revolve,
    _rounded_rect,
    _smooth_curve,
    _to_arrays,
    field_surface,
    grid_edges,
    small_turn,
    strut,
)

#: a stream of its own: the same seed never draws what ``shapes.generate_shape`` draws
SEED_STREAM = 104729
#: first seed of ``agndc val-data`` (training uses 0.., the older validation 1,000,000..)
SEED0 = 2_000_000
#: classes (MANIFEST ``kind``) and their shares of the seeds
CLASSES = ("cad", "organic", "print")
CLASS_WEIGHTS = (0.40, 0.25, 0.35)
#: tilt off the grid axes of the turned CAD and printed shapes, degrees
TILT_DEGREES = (1.0, 15.0)
#: share of CAD and printed shapes left on the grid axes (a signed axis permutation)
ALIGNED_SHARE = 0.4
#: wall thickness of thin parts, in voxels at 64^3 (shapes are ~1 across)
WALL_VOXELS = (1.5, 4.0)
#: samples per unit length of the organic classes' fields
FIELD_SAMPLES = 96
#: thin sheets: first seed, thickness in voxels at 64^3, share left on the grid axes (plates
#: mostly lie on a bed or a scanner's table; the rest are turned 1-15° like the CAD parts)
SHEET_SEED0 = 3_000_000
SHEET_VOXELS = (1.5, 3.0)
SHEET_ALIGNED_SHARE = 0.6
#: thin struts: first seed, bar radius in voxels at 64^3 (a rod under 2 voxels across keeps
#: only part of its section on the grid), share left on the grid axes
STRUT_SEED0 = 4_000_000
STRUT_VOXELS = (0.8, 3.0)
STRUT_ALIGNED_SHARE = 0.5
#: share of the figurines with a scanned look, and their wrinkles' wavelengths (voxels at 64^3)
WRINKLED_SHARE = 0.5
WRINKLE_VOXELS = (3.0, 10.0)


def _voxels(rng, lo: float, hi: float) -> float:
    """A length of ``lo``..``hi`` voxels at 64^3, in the shapes' units."""
    return rng.uniform(lo, hi) / 64.0


# ---------------------------------------------------------------- CAD


def _tilted_part(rng, segs) -> Manifold:
    """A part of the training generator's CAD family, placed by ``_place`` (often tilted)."""
    return _assemble(rng, segs)


def _flange(rng, segs) -> Manifold:
    """A disc with a raised hub, a bore and a circle of 4-8 bolt holes, sometimes a chamfered
    rim."""
    r_out, thick = rng.uniform(0.4, 0.5), rng.uniform(0.06, 0.15)
    r_hub, hub_h = r_out * rng.uniform(0.3, 0.5), thick * rng.uniform(1.0, 3.0)
    disc = Manifold.cylinder(thick, r_out, r_out * rng.choice([1.0, 0.93]), segs * 2)
    hub = Manifold.cylinder(thick + hub_h, r_hub, r_hub, segs)
    body = disc + hub
    r_bore = r_hub * rng.uniform(0.4, 0.7)
    n = int(rng.integers(4, 9))
    r_bolt = rng.uniform(0.04, 0.07)
    r_circle = (r_hub + r_out) / 2
    hole = Manifold.cylinder(4 * hub_h, r_bolt, r_bolt, segs).translate((0, 0, -hub_h))
    cuts = [Manifold.cylinder(4 * hub_h, r_bore, r_bore, segs).translate((0, 0, -hub_h))]
    cuts += [hole.translate((r_circle * np.cos(a), r_circle * np.sin(a), 0))
             for a in 2 * np.pi * (np.arange(n) + rng.uniform()) / n]
    return Manifold.batch_boolean([body, *cuts], OpType.Subtract)


def _gear(rng, segs) -> Manifold:
    """A spur gear: 10-28 trapezoidal teeth, a bore with a key slot, sometimes a hub."""
    teeth = int(rng.integers(10, 29))
    r_tip = 0.5
    r_root = r_tip * (1 - rng.uniform(0.08, 0.18) * 28 / max(teeth, 14))
    # per tooth: root, flank up, tip land, flank down (angles in tooth pitches)
    pattern = np.array([[0.0, r_root], [0.15, r_root], [0.3, r_tip], [0.5, r_tip],
                        [0.65, r_root], [0.85, r_root]])
    turns = (np.arange(teeth)[:, None] + pattern[None, :, 0]).reshape(-1) * 2 * np.pi / teeth
    radii = np.tile(pattern[:, 1], teeth)
    outline = np.stack([radii * np.cos(turns), radii * np.sin(turns)], -1)
    width = rng.uniform(0.1, 0.3)
    body = CrossSection([outline]).extrude(width)
    if rng.random() < 0.5:
        r_hub = r_root * rng.uniform(0.35, 0.5)
        body = body + Manifold.cylinder(width * rng.uniform(1.5, 2.5), r_hub, r_hub, segs)
    r_bore = r_root * rng.uniform(0.15, 0.3)
    bore = Manifold.cylinder(2, r_bore, r_bore, segs).translate((0, 0, -0.5))
    key = Manifold.cube((r_bore * 0.6, r_bore * 0.9, 2)).translate(
        (-r_bore * 0.3, r_bore * 0.6, -0.5))
    return body - (bore + key)


def _bracket(rng, segs) -> Manifold:
    """A bent sheet-metal-like bracket (L or U) 1.5-4 voxels thick at 64^3, with holes in
    its legs and sometimes a gusset."""
    t = _voxels(rng, *WALL_VOXELS)
    length, width = rng.uniform(0.6, 1.0), rng.uniform(0.3, 0.6)
    leg = rng.uniform(0.3, 0.6)
    base = Manifold.cube((length, width, t))
    legs = [Manifold.cube((t, width, leg))]
    if rng.random() < 0.4:  # U: a second leg at the other end
        legs.append(Manifold.cube((t, width, leg)).translate((length - t, 0, 0)))
    body = Manifold.batch_boolean([base, *legs], OpType.Add)
    r = min(width, leg) * rng.uniform(0.08, 0.16)
    hole = Manifold.cylinder(1.0, r, r, segs)
    cuts = [hole.translate((x, width / 2, -0.5))
            for x in np.linspace(0.3, 0.85, int(rng.integers(1, 4))) * length]
    cuts.append(hole.rotate((0, 90, 0)).translate((-0.5, width / 2, leg * 0.6)))
    body = Manifold.batch_boolean([body, *cuts], OpType.Subtract)
    if rng.random() < 0.5:  # a triangular gusset in the corner
        g = rng.uniform(0.15, 0.3)
        tri = CrossSection([np.array([[0.0, 0.0], [g, 0.0], [0.0, g]])])
        gusset = tri.extrude(t).rotate((90, 0, 0)).translate((t, width / 2 + t / 2, t))
        body = body + gusset
    return body


# ---------------------------------------------------------------- organic


def _field_grid(lo: np.ndarray, hi: np.ndarray):
    """Sample axes over the box [lo, hi] (plus a border) and their spacing."""
    step = 1.0 / FIELD_SAMPLES
    axes = [np.arange(a - 3 * step, b + 3 * step, step) for a, b in zip(lo, hi)]
    return axes, step


def _figurine(rng, segs) -> Manifold:
    """A body, a head and 2-6 limbs (ellipsoids and tapered capsules) blended by a smooth
    minimum of their distance fields, so they join with fillets instead of creases."""
    parts = []  # (centre a, end b, radius at a, radius at b)
    body = rng.uniform(0.18, 0.28)
    parts.append((np.zeros(3), np.array([0.0, 0.0, rng.uniform(0.1, 0.3)]), body, body * 0.8))
    head = body * rng.uniform(0.5, 0.8)
    top = parts[0][1] + np.array([0.0, 0.0, body * 0.8 + head * 0.7])
    parts.append((top, top, head, head))
    for _ in range(int(rng.integers(2, 7))):
        root = rng.normal(0, 1, 3)
        root *= body * 0.7 / np.linalg.norm(root)
        direction = root / np.linalg.norm(root) + rng.normal(0, 0.5, 3)
        tip = root + direction / np.linalg.norm(direction) * rng.uniform(0.2, 0.45)
        r = body * rng.uniform(0.2, 0.4)
        parts.append((root, tip, r, r * rng.uniform(0.5, 1.0)))
    ends = np.array([p[:2] for p in parts]).reshape(-1, 3)
    reach = max(p[2] for p in parts)
    axes, step = _field_grid(ends.min(0) - reach, ends.max(0) + reach)
    points = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    k = rng.uniform(0.03, 0.08)  # blend width of the smooth minimum
    blend = np.zeros(len(points))
    for a, b, ra, rb in parts:  # a loop over the 4-8 parts, each vectorised over the points
        ab = b - a
        t = np.clip((points - a) @ ab / max(ab @ ab, 1e-12), 0.0, 1.0)
        d = np.linalg.norm(points - (a + t[:, None] * ab), axis=1) - (ra + t * (rb - ra))
        blend += np.exp(-d / k)
    field = (k * np.log(np.maximum(blend, 1e-300))).reshape([len(x) for x in axes])  # inside > 0
    if rng.random() < WRINKLED_SHARE:  # a scanned look: wrinkles a few voxels across
        field += _wrinkles(rng, axes)
    return field_surface(field, 0.0, np.array([x[0] for x in axes]), step)


def _wrinkles(rng, axes) -> np.ndarray:
    """(X, Y, Z) sum of 8 plane waves of 3-10 voxels wavelength at 64^3 and 0.1-0.4 voxel
    amplitude each, over the sample ``axes`` (each a product of 1-D phasors)."""
    j = 8
    direction = rng.normal(0.0, 1.0, (j, 3))
    wavelength = rng.uniform(*WRINKLE_VOXELS, (j, 1)) / 64.0
    freq = 2 * np.pi * direction / np.linalg.norm(direction, axis=1, keepdims=True) / wavelength
    coef = rng.uniform(0.1, 0.4, j) / 64.0 * np.exp(1j * rng.uniform(0, 2 * np.pi, j))
    w = [np.exp(1j * freq[:, i:i + 1] * ax[None, :]) for i, ax in enumerate(axes)]
    return np.einsum("ji,jk,jl->ikl", coef[:, None] * w[0], w[1], w[2]).imag


def _knot(rng, segs) -> Manifold:
    """A tube along a (p, q) torus knot (trefoil, cinquefoil, ...), a union of capsules."""
    p, q = [(2, 3), (2, 5), (3, 4), (3, 5), (2, 7)][rng.integers(5)]
    t = np.linspace(0, 2 * np.pi, 12 * (p + q), endpoint=False)
    big, small = 0.3, rng.uniform(0.1, 0.16)
    r = (big + small * np.cos(q * t))
    curve = np.stack([r * np.cos(p * t), r * np.sin(p * t), small * np.sin(q * t)], -1)
    curve[:, 2] *= rng.uniform(1.0, 2.0)
    tube = rng.uniform(0.035, 0.06)
    ball = Manifold.sphere(tube, 16)
    pieces = [Manifold.batch_hull([ball.translate(tuple(a)), ball.translate(tuple(b))])
              for a, b in zip(curve, np.roll(curve, -1, axis=0))]
    return Manifold.batch_boolean(pieces, OpType.Add)


# ---------------------------------------------------------------- printed


def _vase(rng, segs) -> Manifold:
    """A vase or cup: a revolved smooth profile hollowed to a wall 1.5-4 voxels thick, open at
    the top, sometimes with a handle."""
    z = np.linspace(0, rng.uniform(0.6, 1.0), 24)
    radius = 0.12 + 0.3 * _smooth_curve(rng, np.linspace(0, 1, 24), 0.3)
    wall = _voxels(rng, *WALL_VOXELS)
    floor = wall * rng.uniform(1.0, 3.0)
    outer = _revolve(np.stack([radius, z], -1), segs * 2)
    inner_profile = np.stack([np.maximum(radius - wall, wall), z + floor], -1)
    inner_profile[-1, 1] = z[-1] + 1.0  # through the top: open
    body = outer - _revolve(inner_profile, segs * 2)
    if rng.random() < 0.35:  # a handle: a torus segment on the side
        ring = CrossSection.circle(wall * 1.5, 16).translate((0.12, 0)).revolve(segs)
        handle = ring.rotate((90, 0, 0)).translate((radius[12], 0, z[12]))
        body = body + (handle - _revolve(np.stack([radius * 0.99, z], -1), segs * 2))
    return body


def _low_poly(rng, segs) -> Manifold:
    """A faceted sculpture: the union of 2-5 convex hulls of 8-20 random points each (flat
    faces at every angle, sharp creases)."""
    hulls = []
    for _ in range(int(rng.integers(2, 6))):
        centre = rng.uniform(-0.25, 0.25, 3)
        points = centre + rng.normal(0, 1, (int(rng.integers(8, 21)), 3)) * rng.uniform(
            0.1, 0.3, 3)
        hulls.append(Manifold.hull_points(points))
    return Manifold.batch_boolean(hulls, OpType.Add)


def _lattice_panel(rng, segs) -> Manifold:
    """A plate with a rim and a honeycomb of hexagonal holes (walls of a few voxels)."""
    w, h = rng.uniform(0.6, 1.0), rng.uniform(0.4, 0.8)
    thick = rng.uniform(0.04, 0.12)
    plate = Manifold.cube((w, h, thick), center=True)
    cell = rng.uniform(0.08, 0.15)
    web = _voxels(rng, 2.0, 4.0)
    hexagon = CrossSection.circle((cell - web) / np.sqrt(3), 6).extrude(2 * thick)
    hexagon = hexagon.translate((0, 0, -thick))
    rim = _voxels(rng, 3.0, 6.0)
    xs = np.arange(-w / 2 + rim + cell / 2, w / 2 - rim - cell / 2, cell * 0.75 * 2 / np.sqrt(3))
    holes = []
    for i, x in enumerate(xs):  # a loop over a dozen columns of holes
        ys = np.arange(-h / 2 + rim + cell / 2, h / 2 - rim - cell / 2 + 1e-9, cell)
        holes += [hexagon.translate((x, y + (cell / 2 if i % 2 else 0.0), 0)) for y in ys
                  if abs(y + (cell / 2 if i % 2 else 0.0)) < h / 2 - rim - cell / 2]
    return Manifold.batch_boolean([plate, *holes], OpType.Subtract) if holes else plate


def _name_plate(rng, segs) -> Manifold:
    """A rounded plate with raised (or engraved) pixel glyphs: 3-6 random 5 x 7 bitmaps, one
    pixel 1.5-3 voxels across at 64^3."""
    n = int(rng.integers(3, 7))
    pixel = _voxels(rng, 1.5, 3.0)
    glyphs = rng.random((n, 7, 5)) < 0.45
    width, height = n * 6 * pixel + 4 * pixel, 11 * pixel
    thick = rng.uniform(0.04, 0.1)
    plate = _rounded_rect(width, height, 1.5 * pixel, segs).extrude(thick)
    k, row, col = np.nonzero(glyphs)
    relief = pixel * rng.uniform(1.0, 2.0)
    engrave = rng.random() < 0.4
    z = thick - relief if engrave else thick - pixel / 4
    cubes = [Manifold.cube((pixel, pixel, relief + pixel / 4)).translate(
        (-width / 2 + 2 * pixel + (6 * g + c) * pixel, -3.5 * pixel + (6 - r) * pixel, z))
        for g, r, c in zip(k, row, col)]
    if not cubes:
        return plate
    return Manifold.batch_boolean([plate, *cubes], OpType.Subtract if engrave else OpType.Add)


def _stepped(rng, segs) -> Manifold:
    """A stepped pyramid or ziggurat: 3-8 stacked boxes, each smaller, sometimes hollow."""
    steps = int(rng.integers(3, 9))
    size = np.array([rng.uniform(0.6, 1.0), rng.uniform(0.6, 1.0)])
    rise = rng.uniform(0.04, 0.12)
    shrink = size / (steps + 1) * rng.uniform(0.5, 1.0)
    boxes = [Manifold.cube((*(size - i * shrink), rise * (i + 1)), center=False).translate(
        (*(-(size - i * shrink) / 2), 0)) for i in range(steps)]
    body = Manifold.batch_boolean(boxes, OpType.Add)
    if rng.random() < 0.3:  # a stair cut into one side
        body = body - Manifold.cube((size[0] / 4, size[1], rise * steps)).translate(
            (-size[0] / 8, size[1] / 4, rise))
    return body


# ---------------------------------------------------------------- thin sheets


def _sheet(rng, segs) -> Manifold:
    """A flat plate ``SHEET_VOXELS`` thick at 64^3, 1 long: a rounded rectangle, a gasket
    (a ring) or an L outline, with 1-8 round holes, sometimes a slot, a window or a pocket
    half the plate deep."""
    t = _voxels(rng, *SHEET_VOXELS)
    outline = int(rng.integers(3))
    if outline == 0:  # rounded rectangle, 1 x 0.4-1
        w, h = 1.0, rng.uniform(0.4, 1.0)
        body = _rounded_rect(w, h, h * rng.uniform(0.02, 0.2), segs).extrude(t)
        inner = np.array([w, h]) / 2 - 0.08
    elif outline == 1:  # gasket: a ring, 1 across
        r_in = rng.uniform(0.15, 0.3)
        ring = CrossSection.circle(0.5, segs * 2) - CrossSection.circle(r_in, segs)
        body = ring.extrude(t)
        inner = None
    else:  # L: two arms 1 and 0.5-1 long
        a, b = rng.uniform(0.2, 0.4), rng.uniform(0.5, 1.0)
        arm1 = CrossSection.square((1.0, a)).translate((-0.5, -b / 2))
        arm2 = CrossSection.square((a, b)).translate((-0.5, -b / 2))
        body = (arm1 + arm2).extrude(t)
        inner = None
    cuts = []
    r_hole = rng.uniform(0.015, 0.06)
    hole = Manifold.cylinder(1.0, r_hole, r_hole, segs).translate((0, 0, -0.5))
    if outline == 1:  # bolt holes on a circle between the bore and the rim
        n = int(rng.integers(3, 9))
        r_circle = (0.5 + r_in) / 2
        cuts += [hole.translate((r_circle * np.cos(x), r_circle * np.sin(x), 0))
                 for x in 2 * np.pi * (np.arange(n) + rng.uniform()) / n]
    elif outline == 0:
        n = int(rng.integers(1, 9))
        cuts += [hole.translate((x, y, 0)) for x, y in
                 rng.uniform(-1, 1, (n, 2)) * np.maximum(inner - r_hole, 0.0)]
        if rng.random() < 0.4:  # a slot
            half = rng.uniform(0.05, 0.15)
            r_slot = rng.uniform(0.015, 0.04)
            end = Manifold.cylinder(1.0, r_slot, r_slot, segs).translate((0, 0, -0.5))
            slot = Manifold.batch_hull([end.translate((-half, 0, 0)), end.translate((half, 0, 0))])
            cuts.append(slot.rotate((0, 0, rng.uniform(0, 180))).translate(
                tuple(rng.uniform(-0.5, 0.5, 2) * np.maximum(inner - half - r_slot, 0.0)) + (0,)))
        if rng.random() < 0.3:  # a rectangular window
            size = rng.uniform(0.1, 0.3, 2) * np.array([1.0, inner[1] / 0.5])
            cuts.append(_rounded_rect(*size, size.min() * 0.2, segs).extrude(1.0).translate(
                (*(rng.uniform(-1, 1, 2) * np.maximum(inner - size / 2, 0.0)), -0.5)))
    else:  # holes along the L's long arm
        n = int(rng.integers(1, 6))
        cuts += [hole.translate((x, -b / 2 + a / 2, 0)) for x in
                 np.linspace(-0.5 + a + 0.05, 0.5 - 0.05, n)]
    if rng.random() < 0.3:  # a pocket half the plate deep, from the top
        size = rng.uniform(0.15, 0.35, 2)
        cuts.append(_rounded_rect(*size, size.min() * 0.2, segs).extrude(t).translate(
            (*rng.uniform(-0.25, 0.25, 2), t / 2)))
    return Manifold.batch_boolean([body, *cuts], OpType.Subtract) if cuts else body


# ---------------------------------------------------------------- thin struts


def _bar_sides(rng) -> int:
    """Square, hexagonal or round bars."""
    return int(rng.choice((4, 6, 48)))


def _stool(rng, segs) -> Manifold:
    """A stool or side table: a seat (a disc or a square, 2-6 voxels thick) on 3-4 splayed
    legs ``STRUT_VOXELS`` in radius, joined by a ring of rungs."""
    r, sides = _voxels(rng, *STRUT_VOXELS), _bar_sides(rng)
    height, width = rng.uniform(0.5, 1.0), rng.uniform(0.5, 1.0)
    seat_t = _voxels(rng, 2.0, 6.0)
    n = int(rng.integers(3, 5))
    if rng.random() < 0.5:
        seat = CrossSection.circle(width / 2, segs).extrude(seat_t)
    else:
        seat = Manifold.cube((width, width, seat_t), center=True).translate((0, 0, seat_t / 2))
    ang = 2 * np.pi * (np.arange(n) + 0.5) / n
    unit = np.column_stack([np.cos(ang), np.sin(ang)])
    top = unit * (width / 2 - 3 * r)
    foot = unit * (width / 2 - 3 * r + rng.uniform(0.0, 0.12))
    legs = [strut((*f, -height), (*t, seat_t / 2), r, sides) for f, t in zip(foot, top)]
    z = -height * rng.uniform(0.4, 0.7)
    ring = top + (foot - top) * (-z / height)
    rungs = [strut((*p, z), (*q, z), r * 0.8, sides) for p, q in zip(ring, np.roll(ring, -1, 0))]
    return Manifold.batch_boolean([seat, *legs, *rungs], OpType.Add)


def _lattice_cube(rng, segs) -> Manifold:
    """A printed lattice block: every edge of a 2-4 cells a side cubic grid a bar (an open
    cage), sometimes each cell's face diagonals too."""
    r, sides = _voxels(rng, *STRUT_VOXELS), _bar_sides(rng)
    cells = np.array([rng.integers(2, 5), rng.integers(1, 5), rng.integers(1, 5)])
    size = cells / cells.max()
    axes = [np.linspace(-s / 2, s / 2, c + 1) for s, c in zip(size, cells)]
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    bars = [strut(p, q, r, sides) for axis in range(3) for p, q in grid_edges(nodes, axis)]
    if rng.random() < 0.4:  # x-bracing in the faces normal to z
        bars += [strut(p, q, r * 0.8, sides) for p, q in zip(
            nodes[:-1, :-1, :].reshape(-1, 3), nodes[1:, 1:, :].reshape(-1, 3))]
    return Manifold.batch_boolean(bars, OpType.Add)


def _mast(rng, segs) -> Manifold:
    """An antenna or signpost: a mast on a round foot, 2-6 crossbars, sometimes stays from
    their ends to the foot."""
    r, sides = _voxels(rng, *STRUT_VOXELS), _bar_sides(rng)
    height = 1.0
    foot_r, foot_t = rng.uniform(0.1, 0.25), _voxels(rng, 2.0, 5.0)
    parts = [Manifold.cylinder(foot_t, foot_r, foot_r * rng.uniform(0.6, 1.0), segs),
             strut((0, 0, foot_t), (0, 0, height), r * rng.uniform(1.0, 1.6), sides)]
    for z in np.sort(rng.uniform(0.35, 0.95, int(rng.integers(2, 7)))):
        half = rng.uniform(0.08, 0.35)
        turn = rng.uniform(0, np.pi)
        d = half * np.array([np.cos(turn), np.sin(turn), 0.0])
        parts.append(strut(np.array([0, 0, z]) - d, np.array([0, 0, z]) + d, r, sides))
        if rng.random() < 0.3:
            parts.append(strut(np.array([0, 0, z]) + d, (0, 0, foot_t), r * 0.7, sides))
    return Manifold.batch_boolean(parts, OpType.Add)


def _spring(rng, segs) -> Manifold:
    """A coil spring or a wire helix: 2-8 turns of a round wire, closed ends sometimes ground
    flat."""
    r = _voxels(rng, *STRUT_VOXELS)
    turns = rng.uniform(2.0, 8.0)
    coil = rng.uniform(0.12, 0.45)
    pitch = max(1.0 / turns, 4.0 * r)
    t = np.linspace(0.0, turns * 2 * np.pi, int(turns * 24) + 1)
    path = np.column_stack([coil * np.cos(t), coil * np.sin(t), pitch * t / (2 * np.pi)])
    ball = Manifold.sphere(r, 16)
    pieces = [Manifold.batch_hull([ball.translate(tuple(p)), ball.translate(tuple(q))])
              for p, q in zip(path[:-1], path[1:])]  # a few hundred short hulls
    m = Manifold.batch_boolean(pieces, OpType.Add)
    if rng.random() < 0.5:  # ground ends
        lo, hi = _bounds(m)
        m = m ^ Manifold.cube(tuple(hi - lo - np.array([0, 0, 2 * r])), center=True).translate(
            tuple((lo + hi) / 2))
    return m


def _pin_plate(rng, segs) -> Manifold:
    """A plate (3-8 voxels thick) with 3-20 thin pins standing on it: a connector, a nail
    board, a hairbrush, the columns of a printed miniature's porch."""
    r, sides = _voxels(rng, *STRUT_VOXELS), _bar_sides(rng)
    w, h = 1.0, rng.uniform(0.3, 1.0)
    t = _voxels(rng, 3.0, 8.0)
    plate = Manifold.cube((w, h, t), center=True)
    n = int(rng.integers(3, 21))
    xy = rng.uniform(-1, 1, (n, 2)) * (np.array([w, h]) / 2 - 3 * r)
    length = rng.uniform(0.1, 0.6)
    pins = [strut((x, y, 0), (x, y, t / 2 + length * rng.uniform(0.6, 1.0)), r, sides)
            for x, y in xy]
    return Manifold.batch_boolean([plate, *pins], OpType.Add)


STRUT_BUILDERS = {"stool": (_stool, 0.25), "lattice_cube": (_lattice_cube, 0.2),
                  "mast": (_mast, 0.2), "spring": (_spring, 0.15), "pin_plate": (_pin_plate, 0.2)}


BUILDERS = {
    "cad": {"tilted_part": (_tilted_part, 0.40), "flange": (_flange, 0.2),
            "gear": (_gear, 0.2), "bracket": (_bracket, 0.2)},
    "organic": {"figurine": (_figurine, 0.6), "knot": (_knot, 0.4)},
    "print": {"vase": (_vase, 0.25), "low_poly": (_low_poly, 0.25),
              "lattice_panel": (_lattice_panel, 0.2), "name_plate": (_name_plate, 0.15),
              "stepped": (_stepped, 0.15)},
}


def _draw(rng, table: dict):
    """A key of ``table`` ({key: (value, weight)}) drawn by weight, and its value."""
    keys = list(table)
    weights = np.array([table[k][1] for k in keys])
    key = keys[rng.choice(len(keys), p=weights / weights.sum())]
    return key, table[key][0]


def _tilt(rng) -> np.ndarray:
    """(3, 3) rotation by 1-15° about a random axis."""
    return small_turn(rng, TILT_DEGREES)


def _place(m: Manifold, rng, kind: str, aligned_share: float = ALIGNED_SHARE) -> Manifold:
    """A signed axis permutation, then (CAD and printed: all but ``aligned_share``) a 1-15°
    tilt, or (organic) a uniform rotation."""
    perm = _random_rotation(rng, aligned=True)
    if kind == "organic":
        turn = _random_rotation(rng, aligned=False)
    else:
        turn = np.eye(3) if rng.random() < aligned_share else _tilt(rng)
    affine = np.zeros((3, 4))
    affine[:, :3] = turn @ perm
    return m.transform(affine)


def class_of(seed: int) -> str:
    """The class (one of ``CLASSES``) of ``validation_shape(seed)``; cheap."""
    # (stream, seed): numpy's SeedSequence reads (seed, stream) and (seed, stream, 0) alike,
    # and the class must not share its draws with attempt 0 of the shape
    rng = np.random.default_rng((SEED_STREAM, seed))
    weights = np.array(CLASS_WEIGHTS)
    return CLASSES[rng.choice(len(CLASSES), p=weights / weights.sum())]


def validation_shape(seed: int) -> tuple[str, str, np.ndarray, np.ndarray]:
    """(class, builder name, (V, 3) float64 vertices, (F, 3) int64 faces) of one seed: a
    closed, outward, edge-manifold mesh, bounding-box centre at the origin, longest side 1."""
    kind = class_of(seed)
    for attempt in range(MAX_ATTEMPTS):
        rng = np.random.default_rng((seed, SEED_STREAM, attempt))
        name, build = _draw(rng, BUILDERS[kind])
        segs = int(rng.integers(24, 65))
        m = build(rng, segs)
        if m.is_empty() or m.status().name != "NoError" or m.volume() <= 0:
            continue
        m = _drop_slivers(_place(m, rng, kind))
        lo, hi = _bounds(m)
        if (hi - lo).min() <= 0.05 * (hi - lo).max():  # a needle or a sheet
            continue
        vertices, faces = _to_arrays(m)
        if _edge_manifold(faces):
            return kind, name, vertices, faces
    raise RuntimeError(f"validation seed {seed}: no usable shape in {MAX_ATTEMPTS} attempts")


def _family_shape(seed: int, stream: int, builders: dict, kind: str, aligned_share: float):
    """(kind, builder name, vertices, faces) of one seed of a family beside the main one: a
    builder of ``builders`` ({name: (function, weight)}, drawn by weight when there are several)
    on the family's own ``stream``, placed by ``_place`` with ``aligned_share`` on the axes."""
    for attempt in range(MAX_ATTEMPTS):
        rng = np.random.default_rng((seed, SEED_STREAM, attempt, stream))
        if len(builders) > 1:
            name, build = _draw(rng, builders)
        else:  # nothing drawn: the sheets keep the shapes of their seeds
            (name, (build, _)), = builders.items()
        m = build(rng, int(rng.integers(24, 65)))
        if m.is_empty() or m.status().name != "NoError" or m.volume() <= 0:
            continue
        m = _place(m, rng, kind, aligned_share=aligned_share)
        vertices, faces = _to_arrays(_drop_slivers(m))
        if _edge_manifold(faces):
            return kind, name, vertices, faces
    raise RuntimeError(f"{name} seed {seed}: no usable shape in {MAX_ATTEMPTS} attempts")


def validation_sheet(seed: int) -> tuple[str, str, np.ndarray, np.ndarray]:
    """``validation_shape`` of the thin-sheet family: ("cad", "sheet", vertices, faces),
    deterministic in the seed (its own stream)."""
    return _family_shape(seed, 1, {"sheet": (_sheet, 1.0)}, "cad", SHEET_ALIGNED_SHARE)


def validation_strut(seed: int) -> tuple[str, str, np.ndarray, np.ndarray]:
    """``validation_shape`` of the thin-strut family: ("print", builder name, vertices,
    faces), deterministic in the seed (its own stream)."""
    return _family_shape(seed, 2, STRUT_BUILDERS, "print", STRUT_ALIGNED_SHARE)


#: the shape functions of ``write_family``'s families and their first seeds
FAMILIES = {"main": validation_shape, "sheets": validation_sheet, "struts": validation_strut}
FIRST_SEEDS = {"main": SEED0, "sheets": SHEET_SEED0, "struts": STRUT_SEED0}


def save_shape(out, file: str, kind: str, shape: str, seed: int, vertices, faces) -> dict:
    """Write one mesh of a scored set as ``out/file``; its ``MANIFEST.csv`` row."""
    from ..gridio import save_mesh

    save_mesh(vertices, faces, Path(out) / file)
    return {"file": file, "kind": kind, "shape": shape, "seed": seed, "faces": len(faces)}


def write_manifest(out, rows: list[dict]) -> None:
    """``out/MANIFEST.csv`` (file, kind, shape, seed, faces): the classes ``agndc eval``
    reports by."""
    with open(Path(out) / "MANIFEST.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def _write_one(args) -> dict:
    seed, out, family = args
    kind, name, vertices, faces = FAMILIES[family](seed)
    return save_shape(out, f"val_{seed}.obj", kind, name, seed, vertices, faces)


def write_family(out, n: int, seed0: int | None = None, workers: int = 2,
                 family: str = "main") -> list[dict]:
    """Write seeds ``seed0 .. seed0 + n - 1`` (default: the family's ``FIRST_SEEDS``) of
    ``family`` ("main", "sheets" or "struts") as OBJ files and ``MANIFEST.csv`` (file, kind,
    shape, seed, faces) into ``out``; returns the manifest rows."""
    if family not in FAMILIES:
        raise ValueError(f"unknown validation family {family!r}; choose one of {list(FAMILIES)}")
    if seed0 is None:
        seed0 = FIRST_SEEDS[family]
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    jobs = [(seed, str(out), family) for seed in range(seed0, seed0 + n)]
    if workers > 1:
        from multiprocessing import get_context

        with get_context("spawn").Pool(workers) as pool:
            rows = pool.map(_write_one, jobs)
    else:
        rows = [_write_one(job) for job in jobs]
    write_manifest(out, rows)
    return rows
