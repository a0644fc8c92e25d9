"""Training data: procedural CAD parts, voxelised with augmentation, labelled at every scale.

A sample is one ``.npz`` file holding the scale-0 input lattice and the labels of every scale
(``labels.make_labels``), plus the recipe that made it (shape seed, resolution, rotation, shift),
so the ground-truth mesh can be regenerated for validation metrics.

Augmentation that matters for binary input happens at voxelisation time, where it changes which
voxel centres fall inside: a random rotation, a random resolution (scale) and a random sub-voxel
shift of the grid. Flips and axis permutations are applied to whole samples at batch time.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..errors import AGNDCError
from ..grid import pad_to_lattice
from ..labels import make_labels
from ..study.shapes import (
    generate_shape,
    is_axis_aligned,
    layered_shape,
    round_aligned,
    round_shape,
    shape_family,
    sheet_shape,
    small_turn,
    spiky_shape,
    strut_shape,
)
from ..voxelize import voxelize

RESOLUTION_RANGE = (32, 128)  # voxels on the longest side (random scale, log-uniform)
#: wrinkles of a scanned surface (``sample_recipe(wrinkled=...)``): the families that get them,
#: the plane waves' count, wavelengths and amplitudes as fractions of the shape's longest side
#: (3-10 and 0.1-0.3 voxels when it spans 64 voxels: finer than the smooth noise of the organic
#: family, whose waves are 25-64 voxels long there)
WRINKLED_FAMILIES = ("organic", "smooth")
WRINKLE_WAVES = 8
WRINKLE_WAVELENGTH = (3 / 64, 10 / 64)
WRINKLE_AMPLITUDE = (0.1 / 64, 0.3 / 64)
#: thin sheets (``sample_recipe(sheets=...)``): thickness in voxels of the sample's own grid
#: (``shapes.sheet_shape``; the shape generator's families are never under 5 % of the longest
#: side thick, 1.6-6.4 voxels at 32-128)
SHEET_VOXELS = (1.5, 4.0)
#: slightly tilted parts (``sample_recipe(tilted=...)``): the turn off the grid axes, degrees,
#: about a random axis. Real parts are often modelled or scanned a few degrees off the axes;
#: the generator gives only aligned or freely turned shapes
TILT_DEGREES = (1.0, 15.0)
#: layered parts (``sample_recipe(layered=...)``): the layer height in voxels of the sample's
#: own grid (``shapes.layered_shape``: caps, lids and stepped plates whose rims, floors, shelves
#: and steps are each about a voxel apart, which the generator's families never are)
LAYER_VOXELS = (0.8, 1.4)


def random_rotation(rng) -> np.ndarray:
    """(3, 3) uniformly random rotation (QR of a Gaussian matrix, sign-fixed)."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    return q


def log_uniform_int(rng, lo: int, hi: int) -> int:
    """An integer in [lo, hi] with log-uniform probability (as many draws in 32..64 as in
    64..128), so small and large grids are both common."""
    return int(min(np.floor(np.exp(rng.uniform(np.log(lo), np.log(hi + 1)))), hi))


def sample_recipe(seed: int, resolution_range=RESOLUTION_RANGE, rotate_fraction=0.0,
                  wrinkled: float = 0.0, sheets: float = 0.0, tilted: float = 0.0,
                  spikes: float = 0.0, layered: float = 0.0, struts: float = 0.0,
                  rounds: float = 0.0) -> dict:
    """The augmentation parameters of sample ``seed`` (deterministic).

    ``generate_shape`` already turns all but ``shapes.AXIS_ALIGNED_FRACTION`` of the seeds by a
    free rotation, so those are never rotated again here; ``rotate_fraction`` is the share of
    the generator's axis-aligned shapes that get a random rotation here. The share of
    grid-aligned samples is ``AXIS_ALIGNED_FRACTION * (1 - rotate_fraction)`` (0.35 by default).
    ``wrinkled`` is the share of the ``WRINKLED_FAMILIES`` samples whose surface gets fine
    wrinkles (``wrinkle_mesh``); its draws come after all others, so the other fields of a seed
    do not depend on it. ``sheets`` is the share of seeds that become a thin sheet instead
    (``shapes.sheet_shape``, ``SHEET_VOXELS`` thick at the recipe's resolution, family
    "sheet", no wrinkles), drawn from a stream of its own: the other seeds' recipes are those
    of ``sheets=0``. ``tilted`` is the share of the grid-aligned samples other than sheets that
    are turned ``TILT_DEGREES`` off the axes instead (another stream of its own; the field
    ``tilt_degrees`` records the angle). ``spikes`` is the share of the samples other than
    sheets whose shape grows sharp spikes a few voxels across (``shapes.spiky_shape`` at the
    recipe's voxel; field ``spikes``, no wrinkles), a stream of its own too. ``layered`` is the
    share of the samples other than sheets and spiky shapes that become a layered part instead
    (``shapes.layered_shape``, layers ``LAYER_VOXELS`` thick at the recipe's resolution, family
    "layered", field ``layer_voxels``, no wrinkles, placed by the shape function alone), from a
    stream of its own. ``struts`` is the share of the samples other than sheets, spiky shapes
    and layered parts that become a frame of thin struts instead (``shapes.strut_shape`` at the
    recipe's voxel, family "struts", field ``struts``, no wrinkles, placed by the shape function
    alone), from a stream of its own. ``rounds`` is the share of the samples other than sheets,
    spiky shapes, layered parts and strut frames that become a part of round features along its
    axes instead (``shapes.round_shape`` at the recipe's voxel, family "round", field
    ``rounds``, no wrinkles, placed by the shape function alone), from a stream of its own. The
    recipe also records the shape family and whether the sample is grid-aligned.
    """
    rng = np.random.default_rng([seed, 1234])
    # every draw is made, used or not, so the later ones do not depend on the branch
    rotation, u_rotate = random_rotation(rng), rng.random()
    generator_aligned = is_axis_aligned(seed)
    rotate = generator_aligned and u_rotate < rotate_fraction  # never a second rotation
    recipe = {
        "seed": int(seed),
        "resolution": log_uniform_int(rng, *resolution_range),
        "rotation": (rotation if rotate else np.eye(3)).tolist(),
        "shift": rng.uniform(-0.5, 0.5, size=3).tolist(),
        "family": shape_family(seed),
        "axis_aligned": generator_aligned and not rotate,
    }
    if wrinkled > 0 and rng.random() < wrinkled and recipe["family"] in WRINKLED_FAMILIES:
        direction = rng.normal(size=(WRINKLE_WAVES, 3))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        recipe["wrinkles"] = {
            "direction": direction.tolist(),
            "wavelength": rng.uniform(*WRINKLE_WAVELENGTH, WRINKLE_WAVES).tolist(),
            "amplitude": rng.uniform(*WRINKLE_AMPLITUDE, WRINKLE_WAVES).tolist(),
            "phase": rng.uniform(0, 2 * np.pi, WRINKLE_WAVES).tolist(),
        }
    sheet_rng = np.random.default_rng([seed, 1234, 5])
    if sheets > 0 and sheet_rng.random() < sheets:
        recipe.pop("wrinkles", None)
        recipe["family"] = "sheet"
        recipe["sheet_voxels"] = float(sheet_rng.uniform(*SHEET_VOXELS))
    tilt_rng = np.random.default_rng([seed, 1234, 7])
    if (tilted > 0 and tilt_rng.random() < tilted and recipe["axis_aligned"]
            and "sheet_voxels" not in recipe):
        turn = small_turn(tilt_rng, TILT_DEGREES)
        recipe["rotation"] = turn.tolist()
        recipe["axis_aligned"] = False
        recipe["tilt_degrees"] = float(np.degrees(np.arccos(np.clip((np.trace(turn) - 1) / 2,
                                                                    -1, 1))))
    spike_rng = np.random.default_rng([seed, 1234, 9])
    if spikes > 0 and spike_rng.random() < spikes and not _replaced(recipe):
        recipe.pop("wrinkles", None)
        recipe["spikes"] = True
    layer_rng = np.random.default_rng([seed, 1234, 11])
    if layered > 0 and layer_rng.random() < layered and not _replaced(recipe):
        _placed_by_its_shape(recipe, "layered", generator_aligned,
                             layer_voxels=float(layer_rng.uniform(*LAYER_VOXELS)))
    strut_rng = np.random.default_rng([seed, 1234, 13])
    if struts > 0 and strut_rng.random() < struts and not _replaced(recipe):
        _placed_by_its_shape(recipe, "struts", generator_aligned, struts=True)
    round_rng = np.random.default_rng([seed, 1234, 17])
    if rounds > 0 and round_rng.random() < rounds and not _replaced(recipe):
        # on the grid axes for most seeds
        _placed_by_its_shape(recipe, "round", round_aligned(seed), rounds=True)
    return recipe


#: the recipe fields of the kinds whose shape replaces the generator's (``sample_recipe``): a
#: seed becomes one of them at most, the first whose draw takes it
REPLACING_KINDS = ("sheet_voxels", "spikes", "layer_voxels", "struts", "rounds")


def _replaced(recipe: dict) -> bool:
    """Whether an earlier kind already replaced the recipe's shape."""
    return any(field in recipe for field in REPLACING_KINDS)


def _placed_by_its_shape(recipe: dict, family: str, axis_aligned: bool, **fields) -> None:
    """Make ``recipe`` a ``family`` sample whose shape function places it (as sheets are): no
    second turn, no wrinkles; ``fields`` name the kind and its parameters."""
    recipe.pop("wrinkles", None)
    recipe.pop("tilt_degrees", None)
    recipe.update(family=family, rotation=np.eye(3).tolist(), axis_aligned=axis_aligned,
                  **fields)


def wrinkle_mesh(vertices: np.ndarray, faces: np.ndarray, wrinkles: dict):
    """The mesh subdivided to edges of a quarter of the shortest wavelength, every vertex moved
    along its normal by a sum of plane waves: (V', 3) float64, (F', 3) int64."""
    import trimesh
    from trimesh.remesh import subdivide_to_size

    wavelength = np.asarray(wrinkles["wavelength"])
    vertices, faces = subdivide_to_size(vertices, faces, wavelength.min() / 4, max_iter=20)
    normals = trimesh.Trimesh(vertices, faces, process=False).vertex_normals  # (V, 3)
    k = 2 * np.pi * np.asarray(wrinkles["direction"]) / wavelength[:, None]  # (W, 3)
    height = np.sin(vertices @ k.T + np.asarray(wrinkles["phase"])) @ np.asarray(
        wrinkles["amplitude"])  # (V,)
    return vertices + normals * height[:, None], np.asarray(faces, dtype=np.int64)


def recipe_mesh(recipe: dict) -> tuple[np.ndarray, np.ndarray]:
    """The ground-truth mesh of a recipe: (V, 3) float64, (F, 3) int64."""
    # one voxel of the recipe's grid: voxelize spans the longest side (1) with resolution - 2
    voxel = 1.0 / (recipe["resolution"] - 2)
    if "sheet_voxels" in recipe:  # divided, not times voxel: the same sheet to the last bit
        vertices, faces = sheet_shape(recipe["seed"],
                                      recipe["sheet_voxels"] / (recipe["resolution"] - 2))
    elif recipe.get("spikes"):
        vertices, faces = spiky_shape(recipe["seed"], voxel)
    elif recipe.get("struts"):
        vertices, faces = strut_shape(recipe["seed"], voxel)
    elif recipe.get("rounds"):
        vertices, faces = round_shape(recipe["seed"], voxel)
    elif "layer_voxels" in recipe:
        vertices, faces = layered_shape(recipe["seed"], voxel, recipe["layer_voxels"] * voxel)
    else:
        vertices, faces = generate_shape(recipe["seed"])
    if "wrinkles" in recipe:
        vertices, faces = wrinkle_mesh(vertices, faces, recipe["wrinkles"])
    return vertices @ np.asarray(recipe["rotation"]).T, faces


def make_sample(recipe: dict) -> dict:
    """Arrays of one training sample: input lattice + labels of scales 0..2."""
    vertices, faces = recipe_mesh(recipe)
    grid = voxelize(vertices, faces, recipe["resolution"], shift=recipe["shift"])
    labels = make_labels(vertices, faces, grid, levels=2)
    arrays = {"lattice": pad_to_lattice(grid.occupancy), "affine": grid.affine}
    for level, scale in enumerate(labels):
        arrays[f"edge{level}"] = scale.edge
        arrays[f"vertex{level}"] = scale.vertex
        arrays[f"quadric{level}"] = scale.quadric
        arrays[f"surface{level}"] = scale.surface
        arrays[f"inside{level}"] = scale.inside
    # the ground truth travels with the sample: validation never depends on the generator
    # version that is installed when it runs
    arrays["mesh_vertices"] = vertices.astype(np.float64)
    arrays["mesh_faces"] = faces.astype(np.int32)
    arrays["recipe"] = np.array(json.dumps(recipe))
    return arrays


def sample_mesh(sample: dict) -> tuple[np.ndarray, np.ndarray]:
    """The ground-truth mesh of a loaded sample (stored; older samples: regenerated)."""
    if "mesh_vertices" in sample:
        return sample["mesh_vertices"], sample["mesh_faces"].astype(np.int64)
    return recipe_mesh(sample["recipe"])


def _write_one(args) -> str:
    recipe, path = args
    path = Path(path)
    if not path.exists():
        # written aside and renamed: a generator killed or running beside another never
        # leaves a truncated sample under the name that "exists" skips
        part = path.with_name(path.name + ".part")
        with open(part, "wb") as f:
            np.savez_compressed(f, **make_sample(recipe))
        part.replace(path)
    return str(path)


def build_dataset(out_dir, n: int, seed0: int = 0, workers: int = 2, progress=True,
                  resolution_range=RESOLUTION_RANGE, wrinkled: float = 0.0,
                  sheets: float = 0.0, tilted: float = 0.0, spikes: float = 0.0,
                  layered: float = 0.0, struts: float = 0.0,
                  rounds: float = 0.0) -> list[Path]:
    """Generate ``n`` samples (seeds seed0..seed0+n-1) into ``out_dir``; existing files are kept
    (so a folder holds one resolution range: use a new folder for another).

    ``resolution_range`` (lo, hi): voxels on the longest side, log-uniform. The default stops at
    128; dev meshes at 128³ suggest larger shapes are needed there
    (docs/experiments/flat-patches.md, docs/experiments/cpu-continuations.md).
    """
    from multiprocessing import get_context

    from tqdm import tqdm

    lo, hi = (int(v) for v in resolution_range)
    if not 8 <= lo <= hi:
        raise AGNDCError(f"training resolutions must satisfy 8 <= lo <= hi, got {lo}..{hi}")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    jobs = [(sample_recipe(seed, (lo, hi), wrinkled=wrinkled, sheets=sheets, tilted=tilted,
                           spikes=spikes, layered=layered, struts=struts, rounds=rounds),
             out_dir / f"sample_{seed:06d}.npz")
            for seed in range(seed0, seed0 + n)]
    if workers > 1:
        with get_context("spawn").Pool(workers) as pool:
            paths = list(tqdm(pool.imap(_write_one, jobs), total=n, desc="data",
                              disable=not progress))
    else:
        paths = [_write_one(job) for job in tqdm(jobs, desc="data", disable=not progress)]
    return [Path(p) for p in paths]


def load_sample(path) -> dict:
    """Read a sample written by ``build_dataset`` into plain arrays (+ ``recipe`` dict)."""
    with np.load(path) as data:
        sample = {key: data[key] for key in data.files}
    sample["recipe"] = json.loads(str(sample["recipe"]))
    return sample


def flip_permute(sample: dict, levels: int, rng) -> dict:
    """Random flips and axis permutation of a whole sample, consistent across scales.

    Flipping axis a maps lattice point p to D-1-p, cell p to D-2-p, the edge leaving p along a to
    the edge leaving D-2-p, and the vertex offset along a to 1 - offset.
    """
    out = dict(sample)
    perm = rng.permutation(3)
    flips = rng.random(3) < 0.5
    for level in range(levels + 1):
        inside = sample[f"inside{level}"].transpose(perm)
        edge = sample[f"edge{level}"].transpose(*perm, 3)[..., perm]
        vertex = sample[f"vertex{level}"].transpose(*perm, 3)[..., perm]
        surface = sample[f"surface{level}"].transpose(perm)
        for axis in np.nonzero(flips)[0]:
            inside = np.flip(inside, axis)
            surface = np.roll(np.flip(surface, axis), -1, axis)  # cell p -> D-2-p
            vertex = np.roll(np.flip(vertex, axis), -1, axis)
            vertex[..., axis] = np.where(surface, 1.0 - vertex[..., axis], 0.0)
            edge = np.flip(edge, axis)
            moved = np.roll(edge[..., axis], -1, axis)  # edge along the flipped axis: p -> D-2-p
            edge = edge.copy()
            edge[..., axis] = moved
        out[f"inside{level}"] = np.ascontiguousarray(inside)
        out[f"surface{level}"] = np.ascontiguousarray(surface)
        out[f"vertex{level}"] = np.ascontiguousarray(vertex)
        out[f"edge{level}"] = np.ascontiguousarray(edge)
    out["lattice"] = out["inside0"]
    return out
