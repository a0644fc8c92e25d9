"""The reconstruction methods: one registry that the API, the CLI, the batch runner, the Blender
add-on and the evaluation read their lists, labels and rules from."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Method:
    """One way to turn a grid into a mesh.

    Attributes:
        name: the value of ``remesh(method=...)`` and ``--method``.
        label: a short display name (object-name suffixes, reports).
        title: the name in menus (Blender's method enum); the label if empty.
        description: one line for help texts and tooltips.
        weights: the shipped checkpoint a learned method loads (``weights/<name>``), else None.
        mesh_only: contours the source mesh's own surface (needs a mesh, not a grid).
        bounded: its dual vertices can be put on a voxelised mesh's bounding box.
        in_blender: offered by the Blender add-on.
        high_margin: empty lattice points a learned method's network is run with past the
            lattice's high end (``inference.predict_lattice``). Training frames every shape one
            lattice layer nearer the low end than the high end; the shipped AGNDC puts a face
            next to the high border up to a quarter voxel too far out, and 2-4 more empty points
            there bring it to the low faces' depth (docs/experiments/high-border-margin.md).
            A multiple of the coarsest pooling step (4) keeps the lattice's pooling phase.
    """

    name: str
    label: str
    description: str
    title: str = ""
    weights: str | None = None
    mesh_only: bool = False
    bounded: bool = False
    in_blender: bool = False
    high_margin: int = 0


REGISTRY = (
    Method("agndc", "AGNDC", "Attention-guided multi-scale neural dual contouring (shipped "
           "weights)", weights="agndc", bounded=True, in_blender=True, high_margin=4),
    Method("agndc_fast", "AGNDC Fast", "AGNDC distilled for speed (no snake convolutions or "
           "attention): 1.5x as fast, as close to the surface, weaker on some creases (shipped "
           "weights)", title="AGNDC fast (distilled)", weights="agndc_student", bounded=True,
           in_blender=True),
    Method("undc", "UNDC", "Single-scale neural dual contouring baseline (shipped weights)",
           weights="undc", bounded=True, in_blender=True),
    Method("surfacenets", "Surface Nets", "Each dual vertex at the mean of its cell's "
           "crossed-edge midpoints (no network)", bounded=True),
    Method("mc", "MC", "Marching cubes of the same grid (no network)", title="Marching Cubes",
           in_blender=True),
    Method("mc_taubin", "MC + Taubin", "Marching cubes followed by Taubin smoothing (no "
           "network)"),
    Method("oracle", "Oracle", "Dual contouring of the mesh's exact intersections: the ceiling "
           "of this contouring (evaluation name of sharp)", mesh_only=True),
    Method("oracle_binary", "Oracle (binary)", "The oracle with what a binary grid cannot tell "
           "put back: an approximate ceiling for grid-only methods (evaluation)", mesh_only=True),
    Method("sharp", "Sharp", "Dual contouring of the mesh's own exact intersections and "
           "normals: flat faces and sharp edges (meshes only; no network)",
           title="Sharp (exact dual contouring)", mesh_only=True, in_blender=True),
)
BY_NAME = {method.name: method for method in REGISTRY}


def title(name: str) -> str:
    """The menu name of a method."""
    method = BY_NAME[name]
    return method.title or method.label

METHODS = tuple(method.name for method in REGISTRY)
#: methods that contour the source mesh's own intersections: mesh input only
MESH_ONLY_METHODS = tuple(m.name for m in REGISTRY if m.mesh_only)
#: default checkpoint name per learned method (agndc_core/weights/<name>.safetensors)
CHECKPOINT_NAMES = {m.name: m.weights for m in REGISTRY if m.weights}
#: methods whose dual vertices can be put on a voxelised mesh's bounding box
#: (``remesh(source_bounds=True)``); the oracles keep their own definitions
BOUNDED_METHODS = tuple(m.name for m in REGISTRY if m.bounded)
#: the add-on's methods, in its menu's order
BLENDER_METHODS = tuple(m.name for m in REGISTRY if m.in_blender)
