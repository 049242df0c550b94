"""Codebook sampling on SO(3), cosine nearest neighbours, npz round trip and bad files."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from paz6d.aae import codebook as cb
from paz6d.backend.viewpoints import in_plane_rotation


def _random_codebook(count=50, latent=6, seed=0):
    rng = np.random.default_rng(seed)
    return cb.Codebook(rng.normal(size=(count, latent)), Rotation.random(count, random_state=seed).as_matrix(),
                       np.tile([10.0, 12.0, 40.0, 50.0], (count, 1)), np.diag([100.0, 100.0, 1.0]), 0.5)


def test_fibonacci_sphere_is_unit_and_balanced():
    points = cb.fibonacci_sphere(2562)
    np.testing.assert_allclose(np.linalg.norm(points, axis=1), 1.0, atol=1e-12)
    assert np.linalg.norm(points.mean(axis=0)) < 1e-3
    # every octant holds ~1/8 of the points
    octants = np.unique((points > 0) @ [1, 2, 4], return_counts=True)[1]
    assert octants.min() > 0.9 * 2562 / 8


def test_look_at_rotations_point_the_camera_at_the_origin():
    directions = np.vstack([cb.fibonacci_sphere(100), [[0, 0, 1], [0, 0, -1]]])
    rotations = cb.look_at_rotations(directions)
    np.testing.assert_allclose(rotations @ rotations.transpose(0, 2, 1), np.broadcast_to(np.eye(3), rotations.shape),
                               atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(rotations), 1.0, atol=1e-12)
    # the camera sits along `direction`; in the camera frame the object->camera direction is -z
    np.testing.assert_allclose(np.einsum("nij,nj->ni", rotations, directions),
                               np.tile([0.0, 0.0, -1.0], (len(directions), 1)), atol=1e-12)


def test_codebook_rotations_compose_in_plane_then_view():
    views = Rotation.random(3, random_state=1).as_matrix()
    rotations = cb.codebook_rotations(views, 4)
    assert rotations.shape == (12, 3, 3)
    expected = Rotation.from_euler("z", 90, degrees=True).as_matrix() @ views[2]
    np.testing.assert_allclose(rotations[2 * 4 + 1], expected, atol=1e-12)
    # in the image (y down), a positive in-plane angle turns +x towards +y
    np.testing.assert_allclose(in_plane_rotation(np.pi / 2) @ [1, 0, 0], [0, 1, 0], atol=1e-12)


def test_codebook_covers_so3_densely():
    rotations = cb.codebook_rotations(cb.look_at_rotations(cb.fibonacci_sphere(300)), 24)
    queries = Rotation.random(200, random_state=3).as_matrix()
    traces = np.einsum("qij,nij->qn", queries, rotations)  # trace(Q^T R)
    nearest = np.degrees(np.arccos(np.clip((traces.max(axis=1) - 1) / 2, -1, 1)))
    assert nearest.max() < 12.0  # 300 views x 15 deg in-plane: worst-case gap about 11 deg


def test_nearest_matches_brute_force_cosine_and_top_k_order():
    book = _random_codebook()
    queries = np.random.default_rng(5).normal(size=(7, 6)) * 3.0
    indices, similarities = book.nearest(queries, top_k=5)
    raw = np.asarray(book.codes, dtype=np.float64)
    for query, row, values in zip(queries, indices, similarities):
        cosine = [float(np.dot(query, code) / np.linalg.norm(query) / np.linalg.norm(code)) for code in raw]
        assert list(row) == list(np.argsort(cosine)[::-1][:5])
        np.testing.assert_allclose(values, np.sort(cosine)[::-1][:5], atol=1e-6)
    single, _ = book.nearest(queries[0])
    assert single.shape == (1, 1) and single[0, 0] == indices[0, 0]
    # an entry's own code finds itself with similarity 1
    own, value = book.nearest(book.codes[17] * 4.0)
    assert own[0, 0] == 17 and value[0, 0] == pytest.approx(1.0, abs=1e-6)


def test_bad_queries_and_inconsistent_codebooks():
    book = _random_codebook()
    with pytest.raises(ValueError, match="codes"):
        book.nearest(np.ones((2, 5)))
    with pytest.raises(ValueError, match="top_k"):
        book.nearest(np.ones(6), top_k=0)
    with pytest.raises(ValueError, match="zeros"):
        book.nearest(np.zeros(6))
    with pytest.raises(ValueError, match="same number"):
        cb.Codebook(np.ones((3, 2)), np.broadcast_to(np.eye(3), (2, 3, 3)), np.ones((3, 4)), np.eye(3), 1.0)


def test_save_load_round_trip_and_corrupt_files(tmp_path):
    book = _random_codebook()
    path = book.save(tmp_path / "codebook.npz")
    loaded = cb.Codebook.load(path)
    np.testing.assert_allclose(loaded.codes, book.codes, atol=1e-7)  # float32 codes are re-normalised on load
    np.testing.assert_array_equal(loaded.rotations, book.rotations)
    assert loaded.render_distance == book.render_distance
    (tmp_path / "bad.npz").write_bytes(b"garbage")
    with pytest.raises(ValueError, match="bad.npz"):
        cb.Codebook.load(tmp_path / "bad.npz")
    np.savez(tmp_path / "partial.npz", codes=book.codes)
    with pytest.raises(ValueError, match="missing field"):
        cb.Codebook.load(tmp_path / "partial.npz")
    with pytest.raises(ValueError, match="not found"):
        cb.Codebook.load(tmp_path / "absent.npz")


def test_neighbour_average_refines_between_entries():
    base = Rotation.from_rotvec([0.3, -0.2, 0.9])
    offsets = Rotation.from_rotvec([[0, 0, 0], [0.05, 0, 0], [-0.05, 0, 0], [0, 0.05, 0], [0, -0.05, 0], [2.0, 0, 0]])
    rotations = (offsets * base).as_matrix()  # a centre, four neighbours ~2.9 deg around it, one far away
    book = cb.Codebook(np.eye(6), rotations, np.tile([0.0, 0.0, 5.0, 5.0], (6, 1)), np.eye(3), 1.0)
    # best match is the +x neighbour; the four neighbours (equal weights) average back to the centre,
    # the far entry (2 rad away) is outside the 15 degree radius and ignored
    indices = np.array([[1, 2, 3, 4, 5]])
    similarities = np.array([[0.9, 0.9, 0.9, 0.9, 0.9]])
    mean = book.neighbour_average(indices, similarities, radius_deg=15.0, temperature=0.02)[0]
    np.testing.assert_allclose(mean, base.as_matrix(), atol=2e-3)  # chordal mean of a symmetric cross
    # with one clearly better match the average stays at it
    sharp = book.neighbour_average(indices, np.array([[0.9, 0.5, 0.5, 0.5, 0.5]]), temperature=0.02)[0]
    np.testing.assert_allclose(sharp, rotations[1], atol=1e-6)
    np.testing.assert_allclose(book.neighbour_average([[5]], [[1.0]])[0], rotations[5], atol=1e-12)
    with pytest.raises(ValueError, match="radius_deg"):
        book.neighbour_average(indices, similarities, radius_deg=0)


def test_within_keeps_the_entries_of_a_viewpoint_range_in_order_and_refuses_an_empty_one():
    from paz6d.backend.viewpoints import ViewpointRange, elevation_and_inplane

    codebook = _random_codebook(count=200, seed=4)
    above = ViewpointRange((0, 90), 60)
    kept = codebook.within(above)
    elevation, inplane = elevation_and_inplane(codebook.rotations)
    expected = np.flatnonzero((elevation >= 0) & (np.abs(inplane) <= 60))  # brute force
    assert 0 < len(kept) == len(expected) < len(codebook)
    np.testing.assert_allclose(kept.codes, codebook.codes[expected], rtol=1e-6)  # unit rows, normalised again
    np.testing.assert_array_equal(kept.rotations, codebook.rotations[expected])
    np.testing.assert_array_equal(kept.render_boxes, codebook.render_boxes[expected])
    assert kept.render_distance == codebook.render_distance and np.array_equal(kept.render_K, codebook.render_K)
    assert len(codebook.within(ViewpointRange())) == len(codebook)
    with pytest.raises(ValueError, match="none of the codebook's 200 views lies within elevation 90..90"):
        codebook.within(ViewpointRange((90, 90), 0))
