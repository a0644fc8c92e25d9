"""Shared fixtures and analytic shapes for the core tests (the trimesh `generic` habit)."""

from pathlib import Path

import numpy as np
import pytest
import trimesh

REPO = Path(__file__).resolve().parents[2]
SHARED = REPO.parent / "shared"
DEV_DATA = SHARED / "data" / "dev"


def randomise_outputs(net, std=0.1, seed=1):
    """Give a cascade random vertex heads and snake offsets (they start at zero), so tests that
    compare two evaluation paths also compare the vertex channels and bent snakes."""
    import torch

    from agndc_core.nn.dffm import DFFM
    from agndc_core.nn.fdm import PredictionHead
    from agndc_core.nn.snake import DSConv

    generator = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for module in net.modules():
            weights = {PredictionHead: lambda m: m.fc2.weight, DFFM: lambda m: m.out.weight,
                       DSConv: lambda m: m.offset.weight}
            for kind, weight in weights.items():
                if isinstance(module, kind):
                    w = weight(module)
                    w.copy_(torch.randn(w.shape, generator=generator) * std)
    return net


def research_script(name: str):
    """A script of ``research/`` (not a package) imported as a module, for its tests; its
    sibling imports resolve as when it is run from the command line."""
    import importlib.util
    import sys

    if str(REPO / "research") not in sys.path:
        sys.path.insert(0, str(REPO / "research"))
    spec = importlib.util.spec_from_file_location(name, REPO / "research" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def rotation(angle, axis):
    return trimesh.transformations.rotation_matrix(angle, axis)


def box(extents=(1.0, 0.6, 0.4), transform=None) -> trimesh.Trimesh:
    mesh = trimesh.creation.box(extents)
    if transform is not None:
        mesh.apply_transform(transform)
    return mesh


def sphere(radius=0.5, subdivisions=5) -> trimesh.Trimesh:
    return trimesh.creation.icosphere(subdivisions, radius)


def cylinder_with_hole(radius=0.5, hole=0.2, height=0.6, sections=96) -> trimesh.Trimesh:
    """A thick washer (genus 1) built with manifold3d, so it is exactly watertight."""
    from manifold3d import Manifold

    outer = Manifold.cylinder(height, radius, radius, sections, True)
    inner = Manifold.cylinder(height * 2, hole, hole, sections, True)
    mesh = (outer - inner).to_mesh()
    return trimesh.Trimesh(np.asarray(mesh.vert_properties)[:, :3], np.asarray(mesh.tri_verts))


def edge_use_counts(faces) -> np.ndarray:
    """How many faces use each undirected edge."""
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return counts


def dev_mesh_paths():
    """Meshes of ../shared/data/dev (skips the test when the folder is missing)."""
    if not DEV_DATA.exists():
        pytest.skip("../shared/data/dev is not beside the checkout")
    from agndc_core.study.evaluate import find_meshes

    return find_meshes(DEV_DATA)
