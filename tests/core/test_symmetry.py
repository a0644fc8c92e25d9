"""symmetry_errors: exact predictors score zero, broken ones are caught, and the cell mapping
of a mirror is its own inverse."""

import numpy as np
import pytest

from agndc_core.grid import pad_to_lattice
from agndc_core.study.symmetry import _unmirror, face_phase_offsets, symmetry_errors
from agndc_core.surfacenets import surface_nets_lattice


def _blob(seed=0, n=14):
    rng = np.random.default_rng(seed)
    x, y, z = np.meshgrid(*[np.arange(n)] * 3, indexing="ij")
    centre = rng.uniform(5, n - 6, 3)
    radii = rng.uniform(2.5, 4.5, 3)
    occupancy = (((x - centre[0]) / radii[0]) ** 2 + ((y - centre[1]) / radii[1]) ** 2
                 + ((z - centre[2]) / radii[2]) ** 2) < 1
    return pad_to_lattice(occupancy)


@pytest.mark.parametrize("seed", range(3))
def test_surface_nets_respects_every_mirror_and_shift(seed):
    errors = symmetry_errors(surface_nets_lattice, _blob(seed))
    assert set(errors) == {"mirror x", "mirror y", "mirror z", "shift x by 1", "shift x by 2",
                           "shift x by 3"}
    assert max(errors.values()) < 1e-6, errors


def test_a_predictor_that_sees_absolute_position_is_caught():
    """Surface nets nudged along x by the lattice's x index: mirroring and shifting change it."""
    def biased(lattice):
        out = surface_nets_lattice(lattice).astype(np.float64)
        out[..., 0] += 0.01 * np.arange(lattice.shape[0])[:, None, None]
        return out

    errors = symmetry_errors(biased, _blob(1))
    assert errors["mirror x"] > 0.01 and errors["shift x by 2"] == pytest.approx(0.02, abs=1e-6)
    assert errors["mirror y"] < 1e-6 and errors["mirror z"] < 1e-6


def test_a_predictor_with_a_handedness_is_caught():
    """A constant pull towards +x is wrong under the x mirror only, by twice the pull."""
    def leaning(lattice):
        out = surface_nets_lattice(lattice).astype(np.float64)
        out[..., 0] += 0.05
        return out

    errors = symmetry_errors(leaning, _blob(2))
    assert errors["mirror x"] == pytest.approx(0.1, abs=1e-6)
    assert max(errors["mirror y"], errors["mirror z"], errors["shift x by 1"]) < 1e-6


def test_unmirror_twice_is_the_identity_on_all_but_the_last_cells():
    offsets = np.random.default_rng(0).random((8, 4, 4, 3))
    back = _unmirror(_unmirror(offsets, 0), 0)
    np.testing.assert_allclose(back[:-1], offsets[:-1])
    assert np.isnan(back[-1]).all()


def test_lattice_sides_must_fit_the_cascade():
    with pytest.raises(ValueError, match="multiples of 4"):
        symmetry_errors(surface_nets_lattice, np.zeros((6, 8, 8), bool))


def _box(lo=(3, 4, 5), hi=(13, 12, 15), shape=(16, 16, 20)):
    occupancy = np.zeros(shape, dtype=bool)
    occupancy[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]] = True
    return occupancy


def test_surface_nets_puts_a_box_face_at_the_same_place_at_every_phase():
    offsets = face_phase_offsets(surface_nets_lattice, _box(), axis=2)
    assert offsets.shape == (4, 2)
    np.testing.assert_allclose(offsets, 0.0, atol=1e-9)


def test_a_predictor_with_a_phase_dependent_bias_is_read_face_by_face():
    """A pull along z that depends on the cell's z index mod 4 shows up as that pull, at the
    phase each face lands on after the shift."""
    pull = np.array([0.2, -0.1, 0.05, 0.0])

    def phased(lattice):
        out = surface_nets_lattice(lattice).astype(np.float64)
        out[..., 2] += pull[np.arange(lattice.shape[2]) % 4][None, None, :]
        return out

    box = _box()
    offsets = face_phase_offsets(phased, box, axis=2)
    # the faces' cells: between points 4|5 (low) and 14|15 (high) of the unshifted lattice
    for shift in range(4):
        np.testing.assert_allclose(offsets[shift], [pull[(4 + shift) % 4], pull[(14 + shift) % 4]])
    # the other axes see no pull
    np.testing.assert_allclose(face_phase_offsets(phased, box, axis=0), 0.0, atol=1e-9)


def test_face_phase_offsets_refuses_a_lattice_without_faces():
    with pytest.raises(ValueError, match="one box"):
        face_phase_offsets(surface_nets_lattice, _blob(0), axis=2, inset=6.0)
