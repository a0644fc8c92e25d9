"""Seeded procedural solids for training data: CAD parts, smooth primitives, organic blobs and
free-form, thin-walled or finely detailed parts (manifold3d booleans, skimage marching cubes).

Every seed belongs to one *family* (``shape_family``), drawn with ``FAMILY_WEIGHTS``:

- ``cad``: one to three parts lined up with gaps. A part is a base body (box, cylinder/frustum,
  extruded polygon or wedge, block with chamfers and fillets of many sizes, rounded box, solid
  of revolution such as a vase, knob or grooved stepped shaft, extruded random profile with
  rounded corners, shelled box or tube) with added features (bosses, ribs, cones) and
  subtracted ones (through-holes, blind pockets, rounded pockets, slots, countersinks, angled
  holes).
- ``smooth``: unions of spheres, ellipsoids, capsules and tori, sometimes with a box or a
  cylinder, then sometimes minus a few more primitives or intersected with one.
- ``organic``: the iso-surface of a sum of random Gaussian blobs (metaballs, some negative,
  sometimes with smooth noise), extracted by marching cubes on a fine grid and Taubin-smoothed;
  sometimes cut flat or drilled.
- ``freeform``: a block under a smooth random height field, a CAD part bent by a smooth space
  warp, a thin-walled part (vessel, finned plate, partitioned tray, bowl), or a body with
  engraved and embossed details 1-3 voxels across at 64^3.

The whole shape then gets a random non-uniform scale and a rotation: a signed axis permutation
for ``AXIS_ALIGNED_FRACTION`` of the seeds (``is_axis_aligned``), a uniform random rotation for
the others, so the set holds both grid-aligned and off-grid creases. The output is normalised
(bounding-box centre at the origin, longest side 1), the frame the metrics and the voxeliser use.

The family and the alignment come from the stream ``default_rng((seed, SEED_STREAM))``, so they
are known without building the shape; everything else is drawn from
``np.random.default_rng((seed, attempt))``. A seed always gives the same arrays; an attempt whose
booleans leave nothing usable is retried with the next ``attempt`` (same family). manifold3d
guarantees a watertight, oriented 2-manifold result (marching-cubes meshes go through its mesh
constructor, which rejects anything else).

Sizes below are in the nominal units of a part before normalisation (a part is ~1 across).
"""

from __future__ import annotations

import numpy as np
from manifold3d import CrossSection, JoinType, Manifold, Mesh64, OpType
from scipy import sparse
from skimage.measure import marching_cubes

#: shape families and their shares of the seeds
FAMILIES = ("cad", "smooth", "organic", "freeform")
FAMILY_WEIGHTS = (0.45, 0.20, 0.20, 0.15)
#: second entropy word of the per-seed stream (family, alignment); attempts use 0..MAX_ATTEMPTS-1
SEED_STREAM = 7919
#: range of circle segments: enough that a hole looks round at 64^3 (a 64-gon deviates from
#: its circle by 0.1 % of the radius), few enough to keep meshes small
SEGMENTS = (24, 64)
#: at least this many segments for round bodies whose whole surface is curved (spheres, tori,
#: vases): a 48-gon deviates by 0.2 % of the radius, under a voxel at 128^3
SMOOTH_SEGMENTS = 48
#: share of shapes left on the grid axes (signed axis permutation instead of a free rotation);
#: the training recipes add no second rotation, so this is the aligned share of the data
AXIS_ALIGNED_FRACTION = 0.35
#: share of CAD shapes made of several disjoint parts
MULTI_PART_FRACTION = 0.25
#: per-axis factor range of the global non-uniform scale
STRETCH = (0.6, 1.4)
#: edge-length range of a base body, nominal units
BODY_SIZE = (0.35, 1.0)
#: wall thickness of shelled bodies as a fraction of the body's smallest side (>= ~2 voxels
#: at 64^3 for typical bodies, so the walls survive voxelisation)
WALL_FRACTION = (0.12, 0.25)
#: fillet radius or chamfer leg as a fraction of the smaller side next to the edge (from about
#: a voxel at 64^3 to nearly half the side)
FILLET_FRACTION = (0.03, 0.45)
#: fine details (grooves, bosses) and thin walls are sized in voxels at this resolution,
#: relative to the longest side of their body
DETAIL_RESOLUTION = 64
DETAIL_VOXELS = (1.0, 3.0)
THIN_VOXELS = (1.5, 3.5)
#: points of a revolved or vessel profile curve
PROFILE_POINTS = 48
#: marching-cubes cells along the longest side of an organic blob's box
BLOB_GRID = 64
#: Taubin smoothing of blob meshes: lambda, mu (|mu| > lambda: no shrinkage), iterations
TAUBIN = (0.5, -0.53, 4)
#: simplification tolerance of blob meshes, nominal units (a voxel at 128^3 is ~8e-3)
BLOB_SIMPLIFY = 1e-3
#: edge length of warped bodies, as a fraction of their longest side
WARP_EDGE = 1 / 32
#: connected components smaller than this share of the total volume are dropped (booleans
#: can leave slivers that are sub-voxel after normalisation)
MIN_COMPONENT_SHARE = 0.02
#: attempts (derived seeds) before falling back to a plain box
MAX_ATTEMPTS = 16


# ---------------------------------------------------------------- seed-level draws


def _seed_draws(seed: int) -> tuple[str, bool]:
    """The family and the axis alignment of ``seed`` (shared by all its attempts)."""
    u_family, u_aligned = np.random.default_rng((seed, SEED_STREAM)).random(2)
    index = np.searchsorted(np.cumsum(FAMILY_WEIGHTS), u_family, side="right")
    return FAMILIES[min(int(index), len(FAMILIES) - 1)], bool(u_aligned < AXIS_ALIGNED_FRACTION)


def shape_family(seed: int) -> str:
    """The family (one of ``FAMILIES``) that ``generate_shape(seed)`` draws from; cheap."""
    return _seed_draws(seed)[0]


def is_axis_aligned(seed: int) -> bool:
    """Whether ``generate_shape(seed)`` keeps its part axes on the grid axes; cheap."""
    return _seed_draws(seed)[1]


def cad_part(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``generate_shape`` of the first CAD-family seed at or after ``seed``: the demo's, the
    benchmarks' and the Blender tests' machined part, whatever family ``seed`` itself draws."""
    while shape_family(seed) != "cad":
        seed += 1
    return generate_shape(seed)


def bevelled_cube(size: float = 1.0, bevel: float = 0.2) -> tuple[np.ndarray, np.ndarray]:
    """A cube with its four vertical edges bevelled (45° chamfers): its top and bottom rims
    are 90° creases, the edges EF1 counts (Low Poly's acceptance shape, the students' crease
    check). (V, 3) float64 vertices, (F, 3) int64 faces, outward."""
    import trimesh

    half = size / 2
    corners = [[sx * (half - bevel), sy * half, z] for sx in (-1, 1) for sy in (-1, 1)
               for z in (-half, half)]
    corners += [[sx * half, sy * (half - bevel), z] for sx in (-1, 1) for sy in (-1, 1)
                for z in (-half, half)]
    mesh = trimesh.convex.convex_hull(np.array(corners))
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


# ---------------------------------------------------------------- 2-D helpers


def _rounded_rect(w: float, h: float, r: float, segs: int) -> CrossSection:
    """Centred ``w`` x ``h`` rectangle with corners rounded to radius ``r`` < min(w, h) / 2."""
    core = CrossSection.square((w - 2 * r, h - 2 * r), center=True)
    return core.offset(r, JoinType.Round, 2.0, segs)


def _slab(section: CrossSection, h: float) -> Manifold:
    """``section`` extruded along z over [-h/2, h/2]."""
    return section.extrude(h).translate((0, 0, -h / 2))


def _smooth_curve(rng, t: np.ndarray, lo: float) -> np.ndarray:
    """(n,) smooth random curve over ``t`` in [0, 1] (1-3 low-frequency waves), range [lo, 1]."""
    k = rng.integers(1, 4)
    freq, phase = rng.uniform(0.3, 1.6, (k, 1)), rng.uniform(0, 2 * np.pi, (k, 1))
    amp = rng.uniform(0.3, 1.0, (k, 1))
    wave = (amp * np.sin(2 * np.pi * freq * t + phase)).sum(axis=0) + rng.uniform(-1, 1) * t
    wave = (wave - wave.min()) / max(np.ptp(wave), 1e-9)
    return lo + (1 - lo) * wave


def _revolve(profile: np.ndarray, segs: int) -> Manifold:
    """Revolve the (n, 2) (radius, z) polyline, closed along the z axis, about z."""
    ends = np.array([[0.0, profile[0, 1]], [0.0, profile[-1, 1]]])
    poly = np.vstack([ends[:1], profile, ends[1:]])
    return CrossSection([poly]).revolve(segs)


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


def _edge_cutter(rng, segs, size: np.ndarray, axis: int) -> Manifold:
    """Tool that chamfers (legs c) or fillets (radius c) one edge along ``axis`` of the centred
    box ``size``. Built for an edge along z through the origin with the box in x, y < 0."""
    other = [i for i in range(3) if i != axis]
    c = rng.uniform(*FILLET_FRACTION) * size[other].min()
    e = 0.1 * c  # overshoot past the faces so the cut is clean
    if rng.random() < 0.5:  # chamfer: beyond the line x + y = -c
        section = CrossSection([np.array([[e, -c - e], [e, e], [-c - e, e]])])
    else:  # fillet: corner square minus the circle that touches both faces
        section = (CrossSection.square((c + e, c + e)).translate((-c, -c))
                   - CrossSection.circle(c, segs).translate((-c, -c)))
    length = 1.5 * size[axis]
    tool = section.extrude(length).translate((0, 0, -length / 2))
    signs = rng.choice([-1.0, 1.0], 2)
    affine = np.zeros((3, 4))
    affine[other[0], 0], affine[other[1], 1], affine[axis, 2] = signs[0], signs[1], 1.0
    if np.linalg.det(affine[:, :3]) < 0:
        affine[axis, 2] = -1.0  # the tool is symmetric in z: keep a proper rotation
    affine[other, 3] = signs * size[other] / 2
    return tool.transform(affine)


def _edged_block(rng, segs) -> Manifold:
    """Box with chamfers and fillets of random sizes on a random subset of its 12 edges."""
    size = rng.uniform(*BODY_SIZE, 3)
    cutters = [_edge_cutter(rng, segs, size, rng.integers(3)) for _ in range(rng.integers(2, 9))]
    return Manifold.cube(size, center=True) - Manifold.batch_boolean(cutters, OpType.Add)


def _rounded_box(rng, segs) -> Manifold:
    """Box filleted on its 4 edges along z, on 8 edges (two crossed rounded bars intersected),
    or on all 12 (hull of 8 corner balls)."""
    size = rng.uniform(*BODY_SIZE, 3)
    r = rng.uniform(*FILLET_FRACTION) * size.min()
    kind = rng.integers(3)
    if kind == 2:
        corners = (np.indices((2, 2, 2)).reshape(3, -1).T * 2 - 1) * (size / 2 - r)  # (8, 3)
        ball = Manifold.sphere(r, max(segs, SMOOTH_SEGMENTS))
        return Manifold.batch_hull([ball.translate(tuple(c)) for c in corners])
    bar = _slab(_rounded_rect(size[0], size[1], r, segs), size[2])
    if kind == 0:
        return bar
    r2 = rng.uniform(*FILLET_FRACTION) * min(size[1], size[2])
    cross = _slab(_rounded_rect(size[2], size[1], r2, segs), size[0])
    return bar ^ cross.rotate((0, 90, 0))  # the second bar runs along x


def _revolved(rng, segs) -> Manifold:
    """Solid of revolution about z: a vase or knob (smooth random radius curve, maybe closing
    in a dome) or a stepped shaft with rectangular and V grooves."""
    h, r_max = rng.uniform(*BODY_SIZE), rng.uniform(0.15, 0.5)
    if rng.random() < 0.5:
        t = np.linspace(0.0, 1.0, PROFILE_POINTS)
        radius = r_max * _smooth_curve(rng, t, lo=0.25)
        if rng.random() < 0.4:  # knob: a rounded dome on top
            radius = radius * np.sqrt(1 - t ** rng.uniform(4, 12))
        return _centre(_revolve(np.column_stack([radius, t * h]), max(segs, SMOOTH_SEGMENTS)))
    n = rng.integers(2, 6)
    z = np.concatenate([[0.0], np.sort(rng.uniform(0.1, 0.9, n - 1)), [1.0]]) * h  # (n + 1,)
    radius = rng.uniform(0.35, 1.0, n) * r_max
    body = _revolve(np.column_stack([np.repeat(radius, 2), np.repeat(z, 2)[1:-1]]), segs)
    unit = max(h, 2 * r_max) / DETAIL_RESOLUTION
    grooves = []
    for _ in range(rng.integers(0, 4)):
        zg = rng.uniform(0.05, 0.95) * h
        rg = radius[min(np.searchsorted(z, zg) - 1, n - 1)]
        depth = min(unit * rng.uniform(1, 4), 0.5 * rg)
        width = unit * rng.uniform(1, 4)
        if rng.random() < 0.5:  # rectangular groove
            ring = np.array([[rg - depth, zg], [rg + unit, zg], [rg + unit, zg + width],
                             [rg - depth, zg + width]])
        else:  # V groove
            ring = np.array([[rg - depth, zg + width / 2], [rg + unit, zg - width / 2],
                             [rg + unit, zg + 1.5 * width]])
        grooves.append(CrossSection([ring]).revolve(segs))
    if grooves:
        body = Manifold.batch_boolean([body, *grooves], OpType.Subtract)
    return _centre(body)


def _profile_extrusion(rng, segs) -> Manifold:
    """Random star-shaped polygon with rounded corners and maybe round holes, extruded
    straight, tapered or twisted."""
    a, n = rng.uniform(*BODY_SIZE), rng.integers(4, 12)
    # jittered angles keep every gap below pi: a simple, counter-clockwise polygon
    ang = (np.arange(n) + rng.uniform(-0.4, 0.4, n)) * 2 * np.pi / n
    rad = 0.5 * a * rng.uniform(0.35, 1.0, n)
    section = CrossSection([rad[:, None] * np.column_stack([np.cos(ang), np.sin(ang)])])
    r = rng.uniform(*FILLET_FRACTION) * 0.3 * a
    if rng.random() < 0.7:  # round the convex corners
        section = section.offset(-r, JoinType.Round, 2.0, segs).offset(r, JoinType.Round, 2.0, segs)
    if rng.random() < 0.5:  # round the concave corners
        section = section.offset(r, JoinType.Round, 2.0, segs).offset(-r, JoinType.Round, 2.0, segs)
    for _ in range(rng.integers(0, 3)):
        hole = CrossSection.circle(rng.uniform(0.04, 0.12) * a, segs)
        section = section - hole.translate(tuple(rng.uniform(-0.15, 0.15, 2) * a))
    h = rng.uniform(*BODY_SIZE)
    twist = rng.uniform(-120, 120) if rng.random() < 0.3 else 0.0
    top = tuple(rng.uniform(0.5, 1.0, 2)) if rng.random() < 0.3 else (1.0, 1.0)
    return _centre(section.extrude(h, 24 if twist else 0, twist, top))


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


BODIES = (_box, _cylinder, _prism, _edged_block, _shell, _rounded_box, _revolved,
          _profile_extrusion)


def _placed(rng, m: Manifold, spread: float) -> Manifold:
    """``m`` moved by a random offset in [-spread, spread]^3."""
    return m.translate(tuple(rng.uniform(-spread, spread, 3)))


def _centre(m: Manifold) -> Manifold:
    """Move the bounding-box centre to the origin."""
    lo, hi = _bounds(m)
    return m.translate(tuple(-(lo + hi) / 2))


def _bounds(m: Manifold) -> tuple[np.ndarray, np.ndarray]:
    """(3,) lower and (3,) upper corner of the bounding box."""
    b = np.asarray(m.bounding_box(), dtype=np.float64)
    return b[:3], b[3:]


# ---------------------------------------------------------------- features


def _face_frame(rng, lo, hi, axes=(0, 1, 2)):
    """A random face (normal along one of ``axes``) of the box [lo, hi]: its axis, outward
    sign (+-1) and a point on it.

    The point stays in the middle 60 % of the face so features land on material even for
    round or slanted bodies whose bounding box is larger than the solid."""
    axis, sign = axes[rng.integers(len(axes))], rng.choice([-1.0, 1.0])
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
    """z-aligned tool with base at z=0: round hole, square or rounded pocket, slot or
    countersink."""
    kind = rng.integers(5)
    r = width / 2
    if kind == 0:
        return Manifold.cylinder(depth, r, r, segs)
    if kind == 1:
        return Manifold.cube((width, width * rng.uniform(0.5, 1.5), depth)).translate((-r, -r, 0))
    if kind == 2:  # slot: hull of two holes
        d = width * rng.uniform(1.0, 2.5)
        pin = Manifold.cylinder(depth, r * 0.6, r * 0.6, segs)
        return Manifold.batch_hull([pin.translate((-d / 2, 0, 0)), pin.translate((d / 2, 0, 0))])
    if kind == 3:  # rounded rectangular pocket, corner radius from sharp-ish to a full round
        length = width * rng.uniform(0.6, 2.0)
        corner = rng.uniform(0.05, 0.49) * min(width, length)
        return _rounded_rect(width, length, corner, segs).extrude(depth)
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


def _detail_tool(rng, segs, lo, hi, axes) -> tuple[Manifold, bool]:
    """A fine feature on a face of the box [lo, hi], 1-3 voxels deep/high and wide at
    ``DETAIL_RESOLUTION``: a line, ring, dot or row of parallel lines. Returns the tool and
    whether it is engraved (subtracted) rather than embossed (added)."""
    axis, sign, point = _face_frame(rng, lo, hi, axes)
    unit = (hi - lo).max() / DETAIL_RESOLUTION
    face = np.delete(hi - lo, axis).min()
    depth, width = unit * rng.uniform(*DETAIL_VOXELS, 2)
    height = depth + unit  # one voxel of overshoot (engraving) or of sinking (embossing)
    kind = rng.integers(4)
    if kind == 0:  # line
        length = face * rng.uniform(0.2, 0.7)
        tool = Manifold.cube((length, width, height)).translate((-length / 2, -width / 2, 0))
    elif kind == 1:  # ring
        r = max(face * rng.uniform(0.06, 0.25), 2 * width)
        bore = Manifold.cylinder(3 * height, r - width, r - width, segs)
        tool = Manifold.cylinder(height, r, r, segs) - bore.translate((0, 0, -height))
    elif kind == 2:  # dot: dimple or boss
        r = unit * rng.uniform(1.0, 4.0)
        tool = Manifold.cylinder(height, r, r, segs)
    else:  # parallel lines (knurl, fins)
        n, length = rng.integers(3, 8), face * rng.uniform(0.2, 0.6)
        pitch = width * rng.uniform(2.0, 4.0)
        line = Manifold.cube((length, width, height)).translate((-length / 2, -width / 2, 0))
        tool = Manifold.batch_boolean(
            [line.translate((0, (i - (n - 1) / 2) * pitch, 0)) for i in range(n)], OpType.Add)
    engrave = rng.random() < 0.6
    tool = tool.rotate((0, 0, rng.uniform(0, 180))).translate((0, 0, -depth if engrave else -unit))
    return _along(tool, axis, sign).translate(tuple(point)), engrave


# ---------------------------------------------------------------- CAD family


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


# ---------------------------------------------------------------- smooth family


def _primitive(rng, segs, scale: float) -> Manifold:
    """Sphere, ellipsoid, (tapered) capsule or torus about ``scale`` across, randomly turned,
    centred at the origin."""
    kind = rng.integers(4)
    r = 0.5 * scale * rng.uniform(0.6, 1.0)
    if kind == 0:
        m = Manifold.sphere(r, segs)
    elif kind == 1:
        m = Manifold.sphere(r, segs).scale(tuple(rng.uniform(0.35, 1.0, 3)))
    elif kind == 2:
        rc = r * rng.uniform(0.2, 0.5)
        ends = (Manifold.sphere(rc, segs).translate((0, 0, rc - r)),
                Manifold.sphere(rc * rng.uniform(0.5, 1.0), segs).translate((0, 0, r - rc)))
        m = Manifold.batch_hull(list(ends))
    else:
        minor = r * rng.uniform(0.15, 0.45)
        m = CrossSection.circle(minor, segs).translate((r - minor, 0)).revolve(segs)
    return m.rotate(tuple(rng.uniform(0, 360, 3)))


def _smooth(rng, segs) -> Manifold:
    """Union of 1-4 overlapping smooth primitives (sometimes with a box or cylinder), then
    sometimes minus 1-2 more primitives or intersected with one."""
    segs = max(segs, SMOOTH_SEGMENTS)
    parts = [_placed(rng, _primitive(rng, segs, rng.uniform(0.4, 1.0)), 0.25)
             for _ in range(rng.integers(1, 5))]
    if rng.random() < 0.2:
        block = _box(rng, segs) if rng.random() < 0.5 else _cylinder(rng, segs)
        parts.append(_placed(rng, block, 0.25))
    body = Manifold.batch_boolean(parts, OpType.Add)
    u = rng.random()
    if u < 0.3:
        cuts = [_placed(rng, _primitive(rng, segs, rng.uniform(0.2, 0.6)), 0.4)
                for _ in range(rng.integers(1, 3))]
        body = Manifold.batch_boolean([body, *cuts], OpType.Subtract)
    elif u < 0.45:
        body = body ^ _placed(rng, _primitive(rng, segs, rng.uniform(0.7, 1.2)), 0.2)
    return body


# ---------------------------------------------------------------- organic family


def _blob_field(rng) -> tuple[np.ndarray, float, np.ndarray, float]:
    """Sampled metaball field: (X, Y, Z) float64 values, iso level, (3,) origin of sample 0
    and the sample spacing. The field is padded with a below-level border, so its iso-surface
    is closed."""
    k = rng.integers(4, 15)
    if rng.random() < 0.5:  # a chain: limbs, worms
        centres = np.cumsum(rng.normal(0.0, 0.14, (k, 3)), axis=0)  # (k, 3)
    else:  # a cluster
        centres = rng.uniform(-0.35, 0.35, (k, 3))
    sigma = rng.uniform(0.06, 0.16, (k, 1)) * rng.uniform(0.6, 1.6, (k, 3))  # (k, 3) anisotropic
    weight = np.where(rng.random(k) < 0.2, -rng.uniform(0.3, 0.8, k), 1.0)  # some dents
    weight[0] = 1.0
    level = rng.uniform(0.3, 0.6)
    lo, hi = (centres - 3.5 * sigma).min(axis=0), (centres + 3.5 * sigma).max(axis=0)
    step = (hi - lo).max() / BLOB_GRID
    axes = [np.arange(a, b + step, step) for a, b in zip(lo, hi)]
    # Gaussians are separable: per-axis factors (k, n_axis), combined by one einsum
    g = [np.exp(-0.5 * ((ax[None, :] - centres[:, i:i + 1]) / sigma[:, i:i + 1]) ** 2)
         for i, ax in enumerate(axes)]
    field = np.einsum("ki,kj,kl->ijl", weight[:, None] * g[0], g[1], g[2])  # (X, Y, Z)
    if rng.random() < 0.6:  # smooth noise: sum of plane waves, each a product of 1-D phasors
        j = 6
        freq = rng.normal(0.0, 1.0, (j, 3))
        freq *= rng.uniform(6.0, 16.0, (j, 1)) / np.linalg.norm(freq, axis=1, keepdims=True)
        coef = rng.uniform(0.02, 0.08, j) * np.exp(1j * rng.uniform(0, 2 * np.pi, j))
        w = [np.exp(1j * freq[:, i:i + 1] * ax[None, :]) for i, ax in enumerate(axes)]
        field += np.einsum("ji,jk,jl->ikl", coef[:, None] * w[0], w[1], w[2]).imag
    field = np.pad(field, 1, constant_values=level - 1.0)
    return field, level, lo - step, step


def _taubin(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Taubin lambda|mu smoothing (Laplacian without shrinkage): (V, 3) -> (V, 3)."""
    lam, mu, steps = TAUBIN
    n = len(verts)
    i, j = faces.ravel(), np.roll(faces, 1, axis=1).ravel()
    adj = sparse.coo_matrix((np.ones(2 * len(i)), (np.r_[i, j], np.r_[j, i])), shape=(n, n))
    adj = adj.tocsr()
    adj.data[:] = 1.0  # every edge is listed by both of its faces
    mean = sparse.diags(1.0 / np.maximum(adj.sum(axis=1).A1, 1.0)) @ adj  # neighbour average
    for _ in range(steps):
        for w in (lam, mu):
            verts = verts + w * (mean @ verts - verts)
    return verts


def field_surface(field: np.ndarray, level: float, origin: np.ndarray,
                  step: float) -> Manifold:
    """The solid where a sampled ``field`` (X, Y, Z) exceeds ``level`` (the field below it on
    the border, so the surface is closed): marching cubes, Taubin smoothing, outward
    orientation, simplification. ``origin``: (3,) position of sample 0; ``step``: spacing."""
    if field.max() <= level:  # e.g. the dents and the noise ate every blob
        return Manifold()
    verts, faces, _, _ = marching_cubes(field, level, spacing=(step, step, step))
    verts = _taubin(verts.astype(np.float64) + origin, faces)
    tri = verts[faces]  # (F, 3, 3)
    if np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() < 0:
        faces = faces[:, ::-1]  # outward orientation: positive signed volume
    body = Manifold(Mesh64(vert_properties=np.ascontiguousarray(verts),
                           tri_verts=np.ascontiguousarray(faces, dtype=np.uint64)))
    return body if body.is_empty() else body.simplify(BLOB_SIMPLIFY)


def _organic(rng, segs) -> Manifold:
    """Metaball iso-surface (marching cubes, Taubin smoothing, simplification); sometimes cut
    flat by a plane or drilled by a CAD cutter."""
    body = field_surface(*_blob_field(rng))
    if body.is_empty():
        return body
    u = rng.random()
    lo, hi = _bounds(body)
    if u < 0.2:  # a flat cut through the lower part along a random direction
        normal = rng.normal(size=3)
        normal /= np.linalg.norm(normal)
        reach = 0.5 * np.abs(normal) @ (hi - lo)
        offset = normal @ (lo + hi) / 2 - reach * rng.uniform(0.2, 0.7)
        body = body.trim_by_plane(tuple(normal), offset)
    elif u < 0.35:
        body = body - _cutter(rng, segs, lo, hi)
    return body


# ---------------------------------------------------------------- free-form family


def _heightfield_block(rng, segs) -> Manifold:
    """Box whose top is a smooth random height field (bumps, dents, waves), the columns below
    stretched to follow it; sometimes pocketed or drilled."""
    size = rng.uniform(*BODY_SIZE, 3)
    size[2] *= rng.uniform(0.3, 0.8)
    m = rng.integers(2, 7)
    cen = rng.uniform(-0.5, 0.5, (m, 2)) * size[:2]  # (m, 2) bump centres
    sig = rng.uniform(0.1, 0.35, m) * size[:2].max()
    amp = rng.uniform(-0.5, 0.8, m) * max(size[2], 0.3 * size[:2].max())
    wave = rng.normal(size=(2, 2)) * 2 * np.pi / size[:2].max()  # 2 plane waves (k_x, k_y)
    wave_amp = rng.uniform(0.0, 0.1, 2) * size[2] * (rng.random() < 0.5)
    phase = rng.uniform(0, 2 * np.pi, 2)

    def lift(p: np.ndarray) -> np.ndarray:  # (n, 3) -> (n, 3)
        d2 = ((p[:, None, :2] - cen) ** 2).sum(axis=-1)  # (n, m)
        h = (amp * np.exp(-0.5 * d2 / sig**2)).sum(axis=1)
        h += np.sin(p[:, :2] @ wave.T + phase) @ wave_amp
        # dents ease off (smoothly) so the top stays above the bottom at -H/2
        h = np.where(h < 0, size[2] * np.expm1(np.minimum(h, 0) / size[2]), h)
        out = p.copy()
        out[:, 2] += (p[:, 2] / size[2] + 0.5) * h  # bottom fixed, top moved by h
        return out

    body = Manifold.cube(size, center=True).refine_to_length(size.max() * WARP_EDGE)
    body = body.warp_batch(lift)
    lo, hi = _bounds(body)
    cuts = [_cutter(rng, segs, lo, hi) for _ in range(rng.integers(0, 3))]
    return Manifold.batch_boolean([body, *cuts], OpType.Subtract) if cuts else body


def _warped_part(rng, segs) -> Manifold:
    """A CAD part bent and bulged by a smooth injective space warp: p + sum of 3 sine
    displacements whose summed Lipschitz constant stays below 0.6."""
    part = _part(rng, segs)
    lo, hi = _bounds(part)
    ext = (hi - lo).max()
    j = 3
    freq = rng.normal(size=(j, 3))
    wavelength = ext * rng.uniform(0.8, 2.5, (j, 1))
    freq *= 2 * np.pi / (wavelength * np.linalg.norm(freq, axis=1, keepdims=True))
    direction = rng.normal(size=(j, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    amp = rng.uniform(0.3, 1.0, j) * 0.6 / (j * np.linalg.norm(freq, axis=1))
    phase = rng.uniform(0, 2 * np.pi, j)

    def bend(p: np.ndarray) -> np.ndarray:  # (n, 3) -> (n, 3)
        return p + (amp * np.sin(p @ freq.T + phase)) @ direction

    return part.refine_to_length(ext * WARP_EDGE).warp_batch(bend)


def _thin_walled(rng, segs) -> Manifold:
    """Walls 1.5-3.5 voxels thick at 64^3: a revolved vessel, a finned plate, a tray with
    partitions, or a bowl."""
    kind = rng.integers(4)
    size = rng.uniform(*BODY_SIZE, 3)
    wall = size.max() * rng.uniform(*THIN_VOXELS) / DETAIL_RESOLUTION
    if kind == 0:  # vessel: wall band of a smooth profile, with a floor
        h, r_max = size[2], rng.uniform(0.2, 0.5)
        wall = max(h, 2 * r_max) * rng.uniform(*THIN_VOXELS) / DETAIL_RESOLUTION
        t = np.linspace(0.0, 1.0, PROFILE_POINTS)
        outer = np.column_stack([r_max * _smooth_curve(rng, t, lo=0.45), t * h])
        inner = outer[t * h >= 1.5 * wall] - [wall, 0.0]
        return _revolve(np.vstack([outer, inner[::-1]]), max(segs, SMOOTH_SEGMENTS))
    if kind == 1:  # plate with thin parallel fins
        base_h = size[2] * rng.uniform(0.1, 0.3)
        base = Manifold.cube((size[0], size[1], base_h))
        n = rng.integers(3, 11)
        pitch = size[0] / n
        fin = Manifold.cube((min(wall, 0.5 * pitch), size[1], size[2]))
        fins = [fin.translate(((i + 0.5) * pitch - wall / 2, 0, 0)) for i in range(n)]
        return Manifold.batch_boolean([base, *fins], OpType.Add)
    if kind == 2:  # open tray with thin walls and 1-3 partitions
        cavity = Manifold.cube(size - 2 * wall, center=True).translate((0, 0, wall))
        tray = Manifold.cube(size, center=True) - cavity
        parts = [Manifold.cube((wall, size[1], size[2]), center=True).translate(
            (rng.uniform(-0.35, 0.35) * size[0], 0, 0)) for _ in range(rng.integers(1, 4))]
        return Manifold.batch_boolean([tray, *parts], OpType.Add)
    radius = 0.5 * size.max()  # bowl: spherical shell cut by a plane, then squashed
    shell = (Manifold.sphere(radius, max(segs, SMOOTH_SEGMENTS))
             - Manifold.sphere(radius - wall, max(segs, SMOOTH_SEGMENTS)))
    shell = shell.trim_by_plane((0, 0, -1), -radius * rng.uniform(-0.3, 0.5))
    return shell.scale((1.0, rng.uniform(0.6, 1.0), rng.uniform(0.6, 1.0)))


def _detailed(rng, segs) -> Manifold:
    """A box, rounded block or cylinder with 3-9 engraved and embossed fine details."""
    size = rng.uniform(*BODY_SIZE, 3)
    kind = rng.integers(3)
    axes = (0, 1, 2)
    if kind == 0:
        body = Manifold.cube(size, center=True)
    elif kind == 1:
        r = rng.uniform(*FILLET_FRACTION) * size[:2].min()
        body = _slab(_rounded_rect(size[0], size[1], r, segs), size[2])
    else:  # details only on the flat ends
        body, axes = Manifold.cylinder(size[2], size[:2].min() / 2, -1.0, segs, True), (2,)
    lo, hi = _bounds(body)
    tools = [_detail_tool(rng, segs, lo, hi, axes) for _ in range(rng.integers(3, 10))]
    adds = [tool for tool, engrave in tools if not engrave]
    cuts = [tool for tool, engrave in tools if engrave]
    if adds:
        body = Manifold.batch_boolean([body, *adds], OpType.Add)
    return Manifold.batch_boolean([body, *cuts], OpType.Subtract) if cuts else body


def _freeform(rng, segs) -> Manifold:
    """One of: height-field block, warped CAD part, thin-walled part, finely detailed body."""
    builders = (_heightfield_block, _warped_part, _thin_walled, _detailed)
    return builders[rng.integers(len(builders))](rng, segs)


BUILDERS = {"cad": _assemble, "smooth": _smooth, "organic": _organic, "freeform": _freeform}


# ---------------------------------------------------------------- assembly


def _random_rotation(rng, aligned: bool) -> np.ndarray:
    """(3, 3) rotation: a signed axis permutation (det +1) or uniform on SO(3)."""
    if aligned:
        m = np.eye(3)[rng.permutation(3)] * rng.choice([-1.0, 1.0], 3)
        if np.linalg.det(m) < 0:
            m[2] = -m[2]
        return m
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q * np.sign(np.diag(r))  # makes the QR factor Haar-uniform
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def small_turn(rng, degrees: tuple[float, float]) -> np.ndarray:
    """(3, 3) rotation by a uniform angle in ``degrees`` about a uniformly random axis
    (Rodrigues' formula)."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = np.radians(rng.uniform(*degrees))
    return _rodrigues(axis, np.sin(angle), np.cos(angle))


def _rodrigues(axis: np.ndarray, sin: float, cos: float) -> np.ndarray:
    """(3, 3) rotation about the unit ``axis`` by the angle of that sine and cosine."""
    k = np.cross(np.eye(3), axis)  # the cross-product matrix: k @ v == axis × v
    return np.eye(3) + sin * k + (1 - cos) * k @ k


def _global_transform(m: Manifold, rng, aligned: bool) -> Manifold:
    """Non-uniform stretch along the part axes, then a rotation."""
    affine = np.zeros((3, 4))
    affine[:, :3] = _random_rotation(rng, aligned) @ np.diag(rng.uniform(*STRETCH, 3))
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


def _edge_manifold(faces: np.ndarray) -> bool:
    """Whether every undirected edge of the (F, 3) faces is shared by exactly two of them.

    manifold3d can hand back an edge used by four triangles where two of its components touch
    along a line (rare); such a mesh is not watertight for trimesh and is retried."""
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)  # (3F, 2)
    _, counts = np.unique(edges[:, 0] * (faces.max() + 1) + edges[:, 1], return_counts=True)
    return bool(np.all(counts == 2))


def _attempt(seed: int, attempt: int) -> Manifold | None:
    """One draw of a shape; None when the booleans left nothing usable."""
    family, aligned = _seed_draws(seed)
    rng = np.random.default_rng((seed, attempt))
    segs = int(rng.integers(SEGMENTS[0], SEGMENTS[1] + 1))
    m = BUILDERS[family](rng, segs)
    if m.is_empty() or m.status().name != "NoError" or m.volume() <= 0:
        return None
    m = _drop_slivers(_global_transform(m, rng, aligned))
    lo, hi = _bounds(m)
    # reject needles and sheets: after normalisation some side would be sub-voxel
    return m if (hi - lo).min() > 0.05 * (hi - lo).max() else None


def generate_shape(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A watertight solid of family ``shape_family(seed)``, deterministic in ``seed``.

    Args:
        seed: non-negative integer.

    Returns:
        vertices: (V, 3) float64, bounding box centred at the origin, longest side 1.
        faces: (F, 3) int64, outward-oriented triangles of a closed 2-manifold.
    """
    for attempt in range(MAX_ATTEMPTS):
        m = _attempt(seed, attempt)
        if m is not None:
            vertices, faces = _to_arrays(m)
            if _edge_manifold(faces):
                return vertices, faces
    return _to_arrays(Manifold.cube((1.0, 0.7, 0.5), center=True))  # never reached in practice


# ---------------------------------------------------------------- thin sheets (training)


def _place_flat_part(rng, m: Manifold, aligned: bool):
    """A sheet's or a layered part's placement: on the grid axes (a signed axis permutation) if
    ``aligned``, otherwise turned 1-10° off them or, for a third, freely. Normalised (V, 3),
    (F, 3) arrays, or None when the result is not edge-manifold (the caller draws again)."""
    if aligned:
        turn = _random_rotation(rng, aligned=True)
    elif rng.random() < 1 / 3:
        turn = _random_rotation(rng, aligned=False)
    else:
        turn = small_turn(rng, (1.0, 10.0)) @ _random_rotation(rng, aligned=True)
    affine = np.zeros((3, 4))
    affine[:, :3] = turn
    vertices, faces = _to_arrays(_drop_slivers(m.transform(affine)))
    return (vertices, faces) if _edge_manifold(faces) else None


def _star_outline(rng, segs, min_radius: float, centred: bool = True) -> CrossSection:
    """A random star-shaped outline with rounded corners, 1 across: 4-11 corners at
    ``min_radius``-1 of the largest radius, about the origin (``centred``: its bounding box's
    centre moved there)."""
    n = int(rng.integers(4, 12))
    ang = (np.arange(n) + rng.uniform(-0.4, 0.4, n)) * 2 * np.pi / n
    rad = 0.5 * rng.uniform(min_radius, 1.0, n)
    section = CrossSection([rad[:, None] * np.column_stack([np.cos(ang), np.sin(ang)])])
    r = rng.uniform(0.01, 0.08)
    section = section.offset(-r, JoinType.Round, 2.0, segs).offset(r, JoinType.Round, 2.0, segs)
    lo, hi = _section_box(section)
    if centred:
        section = section.translate(tuple(-(lo + hi) / 2))
    return section.scale(tuple(np.full(2, 1.0 / (hi - lo).max())))


def sheet_shape(seed: int, thickness: float) -> tuple[np.ndarray, np.ndarray]:
    """A flat plate ``thickness`` thick (a fraction of its longest side, which is 1 after
    normalisation): a random star-shaped outline with rounded corners, 1 across, minus 0-6
    through or blind tools (holes, slots, pockets, countersinks) entering from either face.

    ``generate_shape`` never gives a shape this thin (it rejects a shortest side under 5 % of
    the longest); training recipes ask for sheets by thickness in voxels of their own
    resolution (``training.data.sample_recipe``). Placement: on the grid axes (a signed axis
    permutation) for ``AXIS_ALIGNED_FRACTION`` of the seeds, otherwise turned 1-10° off them or,
    for a third of those, freely. Deterministic in (seed, thickness)."""
    aligned = is_axis_aligned(seed)
    for attempt in range(MAX_ATTEMPTS):
        rng = np.random.default_rng((seed, attempt, 5))
        segs = int(rng.integers(SEGMENTS[0], SEGMENTS[1] + 1))
        body = _star_outline(rng, segs, 0.45, centred=False).extrude(thickness)
        lo, hi = _bounds(body)
        cuts = []
        for _ in range(int(rng.integers(0, 7))):
            width = rng.uniform(0.03, 0.15)
            depth = thickness * (1.5 if rng.random() < 0.7 else rng.uniform(0.3, 0.7))
            tool = _profile_tool(rng, segs, width, depth + 0.05)
            point = np.append(rng.uniform(lo[:2], hi[:2]) * 0.7, 0.0)
            if rng.random() < 0.5:  # from the top face down
                tool = tool.translate((0, 0, -0.05)).rotate((180, 0, 0)).translate(
                    (0, 0, thickness))
            else:
                tool = tool.translate((0, 0, -0.05))
            cuts.append(tool.translate(tuple(point)))
        m = Manifold.batch_boolean([body, *cuts], OpType.Subtract) if cuts else body
        if m.is_empty() or m.status().name != "NoError" or m.volume() <= 0:
            continue
        placed = _place_flat_part(rng, m, aligned)
        if placed is not None:
            return placed
    return _to_arrays(Manifold.cube((1.0, 0.7, thickness), center=True))


# ---------------------------------------------------------------- sharp spikes (training)

#: spiky parts (``spiky_shape``): how many spikes, their base radius and height in voxels of
#: the sample's grid (thin enough that the grid keeps only part of each: a cone under ~1 voxel
#: across leaves no voxel centre inside), and their sides (pyramids and round cones)
SPIKE_COUNT = (2, 10)
SPIKE_RADIUS_VOXELS = (0.6, 3.0)
SPIKE_HEIGHT_VOXELS = (5.0, 25.0)
SPIKE_SIDES = (3, 4, 6, 48)


def _turn_z_to(direction: np.ndarray) -> np.ndarray:
    """(3, 3) rotation taking +z to the unit ``direction`` (about z × direction)."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, direction)
    sin, cos = np.linalg.norm(axis), float(direction @ z)
    if sin < 1e-9:
        return np.diag([1.0, 1.0, 1.0]) if cos > 0 else np.diag([1.0, -1.0, -1.0])
    return _rodrigues(axis / sin, sin, cos)


def spiky_shape(seed: int, voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """``generate_shape(seed)`` with 2-10 sharp spikes standing on its surface along the
    outward normal: cones and 3-, 4- and 6-sided pyramids ``SPIKE_RADIUS_VOXELS`` across at
    the base and ``SPIKE_HEIGHT_VOXELS`` tall, in units of ``voxel`` (a fraction of the longest
    side): spires, crown points, thorns, the teeth of a printed roof. Normalised again (longest
    side 1), so a spike that sticks out past the bounding box shrinks the voxel a little.
    Deterministic in (seed, voxel); the plain shape if the union fails."""
    from ..voxelize import triangle_cross

    vertices, faces = generate_shape(seed)
    body = Manifold(Mesh64(vert_properties=vertices, tri_verts=faces.astype(np.uint32)))
    corners = vertices[faces]  # (F, 3, 3)
    cross = triangle_cross(corners)
    area = np.linalg.norm(cross, axis=1)  # twice the area: only its shares are used
    for attempt in range(MAX_ATTEMPTS):
        rng = np.random.default_rng((seed, attempt, 9))
        count = int(rng.integers(SPIKE_COUNT[0], SPIKE_COUNT[1] + 1))
        face = rng.choice(len(faces), size=count, p=area / area.sum())
        weights = rng.dirichlet(np.ones(3), size=count)  # uniform points of each triangle
        foot = np.einsum("nc,nck->nk", weights, corners[face])
        normal = cross[face] / area[face, None]
        radius = rng.uniform(*SPIKE_RADIUS_VOXELS, count) * voxel
        height = rng.uniform(*SPIKE_HEIGHT_VOXELS, count) * voxel
        sides = rng.choice(SPIKE_SIDES, size=count)
        spikes = []
        for k in range(count):  # a handful of spikes per shape
            affine = np.zeros((3, 4))
            affine[:, :3] = _turn_z_to(normal[k])
            affine[:, 3] = foot[k] - normal[k] * voxel  # sunk a voxel into the surface
            spikes.append(Manifold.cylinder(height[k] + voxel, radius[k], 0.0, int(sides[k]))
                          .transform(affine))
        m = Manifold.batch_boolean([body, *spikes], OpType.Add)
        if m.is_empty() or m.status().name != "NoError":
            continue
        out_vertices, out_faces = _to_arrays(m)
        if _edge_manifold(out_faces):
            return out_vertices, out_faces
    return vertices, faces


# ---------------------------------------------------------------- layered parts (training)

#: layered parts (``layered_shape``): how many layers and how far each layer's outline steps in
#: (negative: out) from the one below, in voxels of the sample's grid (the layer height comes
#: from the recipe, ``training.data.LAYER_VOXELS``)
LAYER_COUNT = (3, 12)
LAYER_STEP_VOXELS = (-2.0, 6.0)


def layered_shape(seed: int, voxel: float, layer: float) -> tuple[np.ndarray, np.ndarray]:
    """A shallow part built of 3-12 layers ``layer`` thick (``voxel`` and ``layer`` are
    fractions of the longest side, which is 1 after normalisation; training asks for layers
    about a voxel of the sample's grid thick): caps, lids, knobs, stepped plates and terraced
    models, whose every rim, recessed floor, shelf and step is one layer from the next. Each
    layer's outline (a disc, a rounded rectangle or a random star, 1 across) steps
    ``LAYER_STEP_VOXELS`` in or out from the one below; then recesses one or two layers deep
    from the top or the bottom, a slot one layer deeper across a recess, a hollow from below
    that leaves the top three or four layers, through holes. ``generate_shape`` never gives a
    shape this shallow nor one whose features are all a voxel apart. Placement: as
    ``sheet_shape``. Deterministic in (seed, voxel, layer)."""
    aligned = is_axis_aligned(seed)
    for attempt in range(MAX_ATTEMPTS):
        rng = np.random.default_rng((seed, attempt, 11))
        segs = int(rng.integers(SEGMENTS[0], SEGMENTS[1] + 1)) * 2
        kind = int(rng.integers(3))
        if kind == 0:
            base = CrossSection.circle(0.5, segs)
        elif kind == 1:
            h = rng.uniform(0.4, 1.0)
            base = _rounded_rect(1.0, h, h * rng.uniform(0.02, 0.3), segs)
        else:
            base = _star_outline(rng, segs, 0.55)
        count = int(rng.integers(LAYER_COUNT[0], LAYER_COUNT[1] + 1))
        inset = np.cumsum(np.where(rng.random(count) < 0.35, 0.0,
                                   rng.uniform(*LAYER_STEP_VOXELS, count))) * voxel
        inset -= inset.min()  # the widest layer keeps the outline
        layers = []
        for k in range(count):  # a dozen layers at most
            section = base.offset(-inset[k], JoinType.Round, 2.0, segs)
            if section.area() > 0.01:
                layers.append(section.extrude(layer * 1.001).translate((0, 0, k * layer)))
        if len(layers) < 2:
            continue
        body = Manifold.batch_boolean(layers, OpType.Add)
        lo, hi = _bounds(body)
        top = hi[2]
        cuts = []
        for _ in range(int(rng.integers(1, 4))):  # recesses from the top or the bottom
            depth = int(rng.integers(1, 3)) * layer
            size = rng.uniform(0.15, 0.6, 2)
            tool = _rounded_rect(*size, size.min() * rng.uniform(0.0, 0.5), segs) \
                if rng.random() < 0.5 else CrossSection.circle(size[0] / 2, segs)
            point = rng.uniform(-0.2, 0.2, 2)
            if rng.random() < 0.7:
                cut = tool.extrude(depth + layer).translate((*point, top - depth))
                if rng.random() < 0.6:  # a slot one layer deeper across the recess
                    width = rng.uniform(1.5, 4.0) * voxel
                    slot = Manifold.cube((size.max() * 0.8, width, 2 * layer), center=True)
                    cuts.append(slot.rotate((0, 0, rng.uniform(0, 180))).translate(
                        (*point, top - depth)))
            else:
                cut = tool.extrude(depth + layer).translate((*point, lo[2] - layer))
            cuts.append(cut)
        if rng.random() < 0.4:  # hollow from below, leaving the top two layers (the deepest
            # recess's) and a shelf of one or two more
            shelf = int(rng.integers(1, 3)) * layer
            cuts.append(base.offset(-inset.max() - rng.uniform(2, 6) * voxel, JoinType.Round,
                                    2.0, segs).extrude(top - shelf - lo[2] - layer)
                        .translate((0, 0, lo[2] - layer)))
        for _ in range(int(rng.integers(0, 4))):  # through holes
            r = rng.uniform(1.0, 5.0) * voxel
            cuts.append(Manifold.cylinder(top - lo[2] + 4 * layer, r, r, segs).translate(
                (*rng.uniform(-0.35, 0.35, 2), lo[2] - 2 * layer)))
        m = Manifold.batch_boolean([body, *cuts], OpType.Subtract)
        if m.is_empty() or m.status().name != "NoError" or m.volume() <= 0:
            continue
        placed = _place_flat_part(rng, m, aligned)
        if placed is not None:
            return placed
    return _to_arrays(Manifold.cube((1.0, 0.7, 4 * layer), center=True))


# ---------------------------------------------------------------- thin struts (training)

#: strut frames (``strut_shape``): the struts' radius in voxels of the sample's grid (from a
#: rod the grid keeps only in part, under 2 voxels across, to a few voxels) and their sides
#: (square, hexagonal and octagonal bars, round rods)
STRUT_RADIUS_VOXELS = (0.7, 3.0)
STRUT_SIDES = (4, 6, 8, 48)


def strut(a, b, radius: float, sides: int) -> Manifold:
    """A bar of ``sides`` sides, ``radius`` about its axis, from point ``a`` to point ``b``
    (3,), each end reaching ``radius`` past its point so that bars meeting there join solidly."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    length = float(np.linalg.norm(b - a))
    axis = (b - a) / length
    affine = np.zeros((3, 4))
    affine[:, :3] = _turn_z_to(axis)
    affine[:, 3] = a - axis * radius
    return Manifold.cylinder(length + 2 * radius, radius, radius, int(sides)).transform(affine)


def grid_edges(nodes: np.ndarray, axis: int) -> np.ndarray:
    """(E, 2, 3) end points of the edges along ``axis`` of a grid of ``nodes`` (X, Y, Z, 3):
    each node paired with its neighbour one step up that axis."""
    a = np.moveaxis(nodes, axis, 0)
    return np.stack([a[:-1], a[1:]], axis=-2).reshape(-1, 2, 3)


def _tower(rng, r: float, sides: int, segs: int) -> list[Manifold]:
    """A pavilion: a base and a roof slab (a disc or a rounded rectangle, 1.5-5 struts thick)
    on 3-12 columns round their rim, sometimes a ring beam half-way and a spire on the roof."""
    height = rng.uniform(0.5, 1.0)
    width = 1.0 - rng.uniform(0.0, 0.2)
    slab = rng.uniform(1.5, 5.0) * r
    round_plan = rng.random() < 0.5
    n = int(rng.integers(3, 13))
    if round_plan:
        plan = CrossSection.circle(width / 2, segs)
        ang = 2 * np.pi * (np.arange(n) + rng.uniform()) / n
        feet = (width / 2 - 2 * r) * np.column_stack([np.cos(ang), np.sin(ang)])
    else:
        depth = width * rng.uniform(0.5, 1.0)
        plan = _rounded_rect(width, depth, depth * rng.uniform(0.0, 0.2), segs)
        k = max(2, n // 2)
        x = np.linspace(-width / 2 + 2 * r, width / 2 - 2 * r, k)
        feet = np.vstack([np.column_stack([x, np.full(k, y)])
                          for y in (-depth / 2 + 2 * r, depth / 2 - 2 * r)])
    parts = [plan.extrude(slab), plan.extrude(slab).translate((0, 0, height - slab))]
    parts += [strut((*f, slab), (*f, height - slab), r, sides) for f in feet]
    if rng.random() < 0.4:  # a ring beam joining the columns half-way
        z = height * rng.uniform(0.3, 0.7)
        # round the rim: a rectangular plan's second row of columns walked backwards
        ring = feet if round_plan else feet[np.r_[:k, 2 * k - 1:k - 1:-1]]
        parts += [strut((*p, z), (*q, z), r, sides) for p, q in zip(ring, np.roll(ring, -1, 0))]
    if rng.random() < 0.4:  # a spire
        parts.append(strut((0, 0, height - slab), (0, 0, height + rng.uniform(0.1, 0.3)), r,
                           sides))
    return parts


def _truss(rng, r: float, sides: int) -> list[Manifold]:
    """A space frame: the nodes of a jittered 2-4 x 1-3 x 1-3 grid, most grid edges a bar, some
    cells crossed by a diagonal."""
    counts = np.array([rng.integers(2, 5), rng.integers(1, 4), rng.integers(1, 4)])
    size = np.array([1.0, *rng.uniform(0.15, 0.8, 2)])
    axes = [np.linspace(-s / 2, s / 2, c + 1) for s, c in zip(size, counts)]
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)  # (cx+1, cy+1, cz+1, 3)
    nodes = nodes + rng.normal(0.0, 0.01, nodes.shape)
    parts = []
    for axis in range(3):
        pairs = grid_edges(nodes, axis)
        keep = rng.random(len(pairs)) < 0.85
        parts += [strut(p, q, r, sides) for p, q in pairs[keep]]
    lo = nodes[:-1, :-1, :-1].reshape(-1, 3)
    hi = nodes[1:, 1:, 1:].reshape(-1, 3)
    cross = rng.random(len(lo)) < 0.4
    parts += [strut(p, q, r, sides) for p, q in zip(lo[cross], hi[cross])]
    return parts


def _railing(rng, r: float, sides: int) -> list[Manifold]:
    """A railing: 2-3 rails 1 long over balusters 3-12 struts apart, thicker posts at the ends,
    on a sill."""
    height = rng.uniform(0.2, 0.6)
    rails = [strut((-0.5, 0, z), (0.5, 0, z), r, sides)
             for z in np.linspace(height, height * rng.uniform(0.1, 0.4), int(rng.integers(2, 4)))]
    spacing = rng.uniform(3.0, 12.0) * r
    xs = np.arange(-0.5 + spacing / 2, 0.5, spacing)
    balusters = [strut((x, 0, 0), (x, 0, height), r, sides) for x in xs]
    post = r * rng.uniform(1.5, 2.5)
    posts = [strut((x, 0, -post), (x, 0, height + post), post, sides) for x in (-0.5, 0.5)]
    sill = Manifold.cube((1.0 + 2 * post, 4 * post, 2 * post), center=True).translate(
        (0, 0, -post))
    return [*rails, *balusters, *posts, sill]


def _rings(rng, r: float, segs: int) -> list[Manifold]:
    """Wire rings: 1-4 tori of tube radius ``r`` and major radius 0.12-0.5, turned freely,
    linked or apart, as in a chain, a handle or a jump ring."""
    parts = []
    for k in range(int(rng.integers(1, 5))):
        major = rng.uniform(0.12, 0.5)
        ring = CrossSection.circle(r, max(8, segs // 3)).translate((major, 0)).revolve(segs)
        affine = np.zeros((3, 4))
        affine[:, :3] = _random_rotation(rng, aligned=rng.random() < 0.5)
        affine[:, 3] = rng.uniform(-0.3, 0.3, 3) * (k > 0)
        parts.append(ring.transform(affine))
    return parts


def strut_shape(seed: int, voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """A frame of thin struts ``STRUT_RADIUS_VOXELS`` in radius (``voxel`` a fraction of the
    longest side, which is 1 after normalisation): a pavilion (two slabs on columns), a space
    frame, a railing or wire rings; square to round bars (``STRUT_SIDES``). Rods a few voxels
    across are where a grid keeps a jagged staircase of a round section, which the training
    shapes (``generate_shape``) never show: columns of printed miniatures, lattices, wires,
    vessels in a segmentation mask. Placement: as ``sheet_shape``. Deterministic in (seed,
    voxel); a single rod if every draw fails."""
    aligned = is_axis_aligned(seed)
    for attempt in range(MAX_ATTEMPTS):
        rng = np.random.default_rng((seed, attempt, 13))
        r = rng.uniform(*STRUT_RADIUS_VOXELS) * voxel
        sides = int(rng.choice(STRUT_SIDES))
        segs = int(rng.integers(SEGMENTS[0], SEGMENTS[1] + 1))
        kind = int(rng.integers(4))
        if kind == 0:
            parts = _tower(rng, r, sides, segs)
        elif kind == 1:
            parts = _truss(rng, r, sides)
        elif kind == 2:
            parts = _railing(rng, r, sides)
        else:
            parts = _rings(rng, r, segs)
        m = Manifold.batch_boolean(parts, OpType.Add)
        if m.is_empty() or m.status().name != "NoError" or m.volume() <= 0:
            continue
        placed = _place_flat_part(rng, m, aligned)
        if placed is not None:
            return placed
    return _to_arrays(strut((-0.5, 0, 0), (0.5, 0, 0), 2 * voxel, 48))


# ---------------------------------------------------------------- round parts (training)

#: round parts (``round_shape``): the radius of pins, bosses, holes and shafts, and a tube's
#: wall, in voxels of the sample's grid (from a pin the grid keeps as a jagged staircase to a
#: boss whose side is a long run of terraces); a part's base plate, thickness in voxels
ROUND_RADIUS_VOXELS = (1.5, 12.0)
ROUND_WALL_VOXELS = (1.2, 4.0)
ROUND_PLATE_VOXELS = (2.0, 10.0)
#: the share of round parts whose axes are grid axes (the rest are turned 1-10 degrees off
#: them or freely, as sheets are)
ROUND_ALIGNED = 0.75
#: segments of a round side: facets far finer than a voxel at 128 voxels
ROUND_SEGMENTS = 96


def _round_feature(rng, voxel: float, lo: np.ndarray, hi: np.ndarray) -> tuple[Manifold, bool]:
    """One round feature on the top or bottom face of the box ``lo``..``hi``, its axis along z
    (a shaft: along x or y), its centre at a random point: (tool, True to add it, False to cut
    it). Pins, bosses with a bore, thin-walled tubes and cups, shafts lying on the face, through
    holes and counterbored holes."""
    r = rng.uniform(*ROUND_RADIUS_VOXELS) * voxel
    size = hi - lo
    x, y = lo[:2] + size[:2] * rng.uniform(0.1, 0.9, 2)
    up = rng.random() < 0.6
    face = hi[2] if up else lo[2]
    height = min(rng.uniform(2.0, 30.0) * voxel, 0.35)
    kind = int(rng.integers(5))
    if kind == 3:  # a through hole, counterbored on one side for half of them
        r = min(r, 0.3 * size[:2].min())
        hole = Manifold.cylinder(size[2] + 4 * voxel, r, r, ROUND_SEGMENTS).translate(
            (x, y, lo[2] - 2 * voxel))
        if rng.random() < 0.5:
            depth = min(rng.uniform(1.0, 4.0) * voxel, 0.5 * size[2])
            r2 = r + rng.uniform(1.0, 4.0) * voxel
            bore = Manifold.cylinder(depth + voxel, r2, r2, ROUND_SEGMENTS).translate(
                (x, y, face - depth if up else face - voxel))
            hole = hole + bore
        return hole, False
    if kind == 4:  # a shaft lying on the face along x or y
        length = rng.uniform(0.3, 0.9) * size[:2].max()
        shaft = Manifold.cylinder(length, r, r, ROUND_SEGMENTS, center=True)
        shaft = shaft.rotate((0.0, 90.0, 0.0) if rng.random() < 0.5 else (90.0, 0.0, 0.0))
        sink = rng.uniform(0.2, 0.8) * r  # into the face, so that it joins solidly
        return shaft.translate((x, y, face + (r - sink if up else sink - r))), True
    post = Manifold.cylinder(height + voxel, r, r, ROUND_SEGMENTS)
    if kind == 1:  # a boss: a pin with a bore down its axis
        bore_r = r - rng.uniform(1.0, 4.0) * voxel
        if bore_r > voxel:
            post = post - Manifold.cylinder(height + 3 * voxel, bore_r, bore_r,
                                            ROUND_SEGMENTS).translate((0, 0, voxel))
    elif kind == 2:  # a thin-walled tube or cup: a cylinder's wall a few voxels thick
        r = max(r, 3.0 * voxel)
        wall = rng.uniform(*ROUND_WALL_VOXELS) * voxel
        floor = rng.uniform(1.0, 3.0) * voxel if rng.random() < 0.5 else 0.0
        post = Manifold.cylinder(height + voxel, r, r, ROUND_SEGMENTS) - Manifold.cylinder(
            height + voxel, r - wall, r - wall, ROUND_SEGMENTS).translate((0, 0, voxel + floor))
    post = post.translate((x, y, face - voxel))
    return (post if up else post.mirror((0, 0, 1)).translate((0, 0, 2 * face))), True


def round_aligned(seed: int) -> bool:
    """Whether round part ``seed``'s axes are grid axes (``ROUND_ALIGNED`` of the seeds)."""
    return bool(np.random.default_rng((seed, 17)).random() < ROUND_ALIGNED)


def round_shape(seed: int, voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """A part of round features along its axes (``voxel`` a fraction of the longest side, which
    is 1 after normalisation): a plate ``ROUND_PLATE_VOXELS`` thick or a block, carrying 2-8
    pins, bosses with bores, thin-walled tubes and cups, shafts lying on a face, through holes
    and counterbores (``_round_feature``), radii ``ROUND_RADIUS_VOXELS``, every centre at a
    random point of the lattice's period. Along a grid axis a round side reaches the grid as
    terraces whose steps run parallel to its axis, as a slightly tilted plane's do; the
    generator's shapes are seldom round along an axis and a few voxels across, where real parts
    (pins, screws, bosses, tubes) often are. Placement: on the grid axes where
    ``round_aligned``, otherwise as ``sheet_shape``'s turned parts. Deterministic in (seed, voxel);
    a plate with one pin if every draw fails."""
    for attempt in range(MAX_ATTEMPTS):
        rng = np.random.default_rng((seed, attempt, 17))
        width = rng.uniform(0.3, 0.8)
        if rng.random() < 0.6:
            thickness = rng.uniform(*ROUND_PLATE_VOXELS) * voxel
        else:
            thickness = rng.uniform(0.1, 0.35)
        body = Manifold.cube((1.0, width, thickness), center=True)
        lo, hi = _bounds(body)
        tools = [_round_feature(rng, voxel, lo, hi) for _ in range(int(rng.integers(2, 9)))]
        adds = [tool for tool, add in tools if add]
        cuts = [tool for tool, add in tools if not add]
        if adds:
            body = Manifold.batch_boolean([body, *adds], OpType.Add)
        m = Manifold.batch_boolean([body, *cuts], OpType.Subtract) if cuts else body
        if m.is_empty() or m.status().name != "NoError" or m.volume() <= 0:
            continue
        placed = _place_flat_part(rng, m, round_aligned(seed))
        if placed is not None:
            return placed
    pin = Manifold.cylinder(0.2, 0.1, 0.1, ROUND_SEGMENTS).translate((0, 0, 2 * voxel))
    return _to_arrays(Manifold.cube((1.0, 0.5, 4 * voxel), center=True) + pin)


def _section_box(section: CrossSection) -> tuple[np.ndarray, np.ndarray]:
    """(2,) min and max corners of a cross-section."""
    box = section.bounds()
    return np.asarray(box[:2], dtype=float), np.asarray(box[2:], dtype=float)


def generate_dataset(n: int, seed0: int = 0):
    """Yield ``(seed, vertices, faces)`` for seeds ``seed0 .. seed0 + n - 1``."""
    for seed in range(seed0, seed0 + n):
        yield (seed, *generate_shape(seed))
