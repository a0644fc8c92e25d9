"""Colours of voxel art: each voxel's palette index (MagicaVoxel ``.vox``) carried onto the faces
of a remeshed mesh, and written out as one material per colour (.glb) or face colours (.ply).

A face takes the colour of the nearest occupied voxel *behind* it: its centroid is moved half a
voxel against its outward normal (to the centre of the voxel layer the face bounds) and the
nearest surface voxel centre to that point gives the index. So the two sides of a wall two
voxels thick, one voxel of each colour, each get their own colour, which the face centroid
alone (half a voxel outside) could not tell apart at the wall's edges.

Palette colours are sRGB bytes (as MagicaVoxel shows them); glTF's ``baseColorFactor`` and
Blender's Principled BSDF base colour are linear, so both receive ``srgb_to_linear``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .errors import GridError

if TYPE_CHECKING:
    from .grid import VoxelGrid

#: how far behind a face its colour is read, in voxels (index units): half a voxel reaches the
#: centre of the voxel layer that the face bounds
INSIDE_OFFSET = 0.5
#: name of the material of a palette colour: ``vox_`` and its sRGB hex, so materials of the
#: same colour are shared between imports and files
MATERIAL_PREFIX = "vox_"


@dataclass
class VoxelColors:
    """Per-voxel palette indices and the palette they index.

    Attributes:
        indices: (X, Y, Z) uint8, the palette index of each voxel; 0 where it is empty.
        palette: (256, 4) uint8 sRGB(A), row ``i`` the colour of index ``i`` (row 0 unused).
    """

    indices: np.ndarray
    palette: np.ndarray

    def __post_init__(self) -> None:
        self.indices = np.ascontiguousarray(self.indices, dtype=np.uint8)
        palette = np.asarray(self.palette)
        if self.indices.ndim != 3 or palette.shape != (256, 4):
            raise GridError(f"colour indices must be (X, Y, Z) and the palette (256, 4), got "
                            f"{self.indices.shape} and {palette.shape}")
        self.palette = palette.astype(np.uint8)

    @property
    def used(self) -> np.ndarray:
        """(K,) uint8 sorted palette indices of the occupied voxels."""
        return np.flatnonzero(np.bincount(self.indices.ravel(), minlength=256)[1:]).astype(
            np.uint8) + 1


def face_colors(vertices: np.ndarray, faces: np.ndarray, grid: VoxelGrid) -> np.ndarray:
    """Palette index of each face: the nearest occupied voxel just behind its centroid.

    Args:
        vertices: (V, 3) float world coordinates (``remesh``'s output); faces: (F, 3) int,
            wound outward.
        grid: the coloured source grid (``grid.colors`` set), whose affine placed the mesh.

    Returns:
        (F,) uint8 palette indices (all >= 1).
    """
    if grid.colors is None:
        raise GridError(f"{grid.source}: the grid has no colours")
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(faces) == 0:
        return np.zeros(0, dtype=np.uint8)
    corners = grid.world_to_index(vertices)[faces]  # (F, 3, 3) index coordinates
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])  # (F, 3)
    # faces are wound outward in world space (pipeline.orient_to_affine): a mirroring affine
    # turns them inward in index space
    normal *= np.sign(np.linalg.det(grid.affine[:3, :3]))
    length = np.linalg.norm(normal, axis=1, keepdims=True)  # (F, 1)
    unit = normal / np.where(length > 0, length, 1.0)  # degenerate faces: the centroid itself
    probe = corners.mean(axis=1) - INSIDE_OFFSET * unit  # (F, 3)
    voxels = surface_voxels(grid.occupancy)  # (N, 3)
    from scipy.spatial import cKDTree

    _, nearest = cKDTree(voxels).query(probe)
    return grid.colors.indices[tuple(voxels[nearest].T)]


def result_colors(result) -> dict:
    """``save_mesh``'s colour arguments for a ``RemeshResult``: ``face_colors`` and ``palette``
    when its grid is coloured, else none (the file is then plain geometry)."""
    grid = result.grid
    if grid is None or grid.colors is None or len(result.faces) == 0:
        return {}
    return {"face_colors": face_colors(result.vertices, result.faces, grid),
            "palette": grid.colors.palette}


def surface_voxels(occupancy: np.ndarray) -> np.ndarray:
    """(N, 3) int64 indices of the occupied voxels with an empty (or outside) face neighbour:
    the only ones a face can be nearest to, so the KD-tree holds a shell, not the volume."""
    from scipy.ndimage import binary_erosion

    occupancy = np.asarray(occupancy, dtype=bool)
    return np.argwhere(occupancy & ~binary_erosion(occupancy, border_value=0))


def material_slots(face_index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(K,) uint8 used palette indices, sorted, and the (F,) int32 slot of each face in them."""
    used, slot = np.unique(np.asarray(face_index, dtype=np.uint8), return_inverse=True)
    return used, slot.astype(np.int32).reshape(-1)


def group_faces(face_index: np.ndarray) -> dict[int, np.ndarray]:
    """{palette index: (n,) int64 face indices} for each used colour, in index order."""
    used, slot = material_slots(face_index)
    return {int(index): np.flatnonzero(slot == k) for k, index in enumerate(used)}


def srgb_to_linear(rgba: np.ndarray) -> np.ndarray:
    """(..., 4) uint8 sRGB colours -> (..., 4) float64 linear RGB and alpha in [0, 1]."""
    values = np.asarray(rgba, dtype=np.float64) / 255.0
    rgb = values[..., :3]
    linear = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    return np.concatenate([linear, values[..., 3:]], axis=-1)


def material_name(rgba: np.ndarray) -> str:
    """``vox_rrggbb`` (sRGB hex) for a (4,) or (3,) uint8 colour."""
    r, g, b = (int(c) for c in np.asarray(rgba)[:3])
    return f"{MATERIAL_PREFIX}{r:02x}{g:02x}{b:02x}"


# --- files ----------------------------------------------------------------------------------


def colored_mesh_bytes(vertices: np.ndarray, faces: np.ndarray, face_index: np.ndarray,
                       palette: np.ndarray, file_type: str) -> bytes | None:
    """A coloured mesh file's bytes, or None for a format that carries no colours here.

    ``glb``: one mesh (node) per used colour, each with its material (``material_name``,
    base colour the palette colour, rough and not metallic), so glTF importers (Blender,
    three.js) show the colours without vertex-colour settings; the parts share their vertex
    positions, so welding them again gives the closed mesh. ``ply``: the one mesh, with each
    face's sRGB(A) colour as the face's red, green, blue, alpha.
    """
    if file_type == "glb":
        return _glb(vertices, faces, face_index, palette)
    if file_type == "ply":
        import trimesh

        mesh = trimesh.Trimesh(vertices, faces, process=False,
                               face_colors=np.asarray(palette, np.uint8)[face_index])
        return mesh.export(file_type="ply")
    return None


def _glb(vertices, faces, face_index, palette) -> bytes:
    import trimesh
    from trimesh.visual.material import PBRMaterial

    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    scene = trimesh.Scene()
    linear = {}
    for index, members in group_faces(face_index).items():  # one loop step per colour
        name = material_name(palette[index])
        linear[name] = srgb_to_linear(palette[index]).tolist()
        part = trimesh.Trimesh(vertices, faces[members], process=False)
        part.remove_unreferenced_vertices()
        part.visual = trimesh.visual.TextureVisuals(material=PBRMaterial(
            name=name, baseColorFactor=palette[index], metallicFactor=0.0, roughnessFactor=1.0))
        scene.add_geometry(part, geom_name=name, node_name=name)

    def exact_colors(tree: dict) -> None:
        # trimesh keeps a base colour as uint8; the linear value needs the full float
        for material in tree.get("materials", []):
            if material.get("name") in linear:
                material.setdefault("pbrMetallicRoughness", {})["baseColorFactor"] = \
                    linear[material["name"]]

    return scene.export(file_type="glb", tree_postprocessor=exact_colors)
