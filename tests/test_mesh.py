"""paz6d.backend.mesh: loading PLY/OBJ/GLB, units, diameter (vs brute force and BOP's
models_info.json), surface sampling, bounding boxes and errors for broken files."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from scipy.spatial.distance import pdist

from paz6d.backend import mesh
from paz6d.backend.mesh import MeshError


@pytest.fixture(scope="module")
def lmo_models(shared_data) -> dict[str, trimesh.Trimesh]:
    """LM-O meshes in metres keyed by BOP object id."""
    paths = sorted((shared_data / "bop_lmo" / "models").glob("obj_*.ply"))
    return {str(int(path.stem.split("_")[1])): mesh.load_mesh(path, scale=0.001) for path in paths}


@pytest.fixture(scope="module")
def models_info(shared_data) -> dict:
    return json.loads((shared_data / "bop_lmo" / "models" / "models_info.json").read_text())


def header_vertex_count(path) -> int:
    with open(path, "rb") as stream:
        for line in stream:
            if line.startswith(b"element vertex"):
                return int(line.split()[-1])
    raise AssertionError(f"{path}: no vertex count in the PLY header")


def test_lmo_ply_loads_in_metres_with_colours(shared_data, lmo_models, models_info):
    assert sorted(lmo_models, key=int) == sorted(models_info, key=int)
    for object_id, model in lmo_models.items():
        path = shared_data / "bop_lmo" / "models" / f"obj_{int(object_id):06d}.ply"
        assert len(model.vertices) == header_vertex_count(path)
        assert model.visual.kind == "vertex"
        info = models_info[object_id]
        low = np.array([info["min_x"], info["min_y"], info["min_z"]]) / 1000
        size = np.array([info["size_x"], info["size_y"], info["size_z"]]) / 1000
        corner_low, corner_high = mesh.bounding_box(model.vertices)
        np.testing.assert_allclose(corner_low, low, atol=1e-5)  # models_info rounds to 1e-4 mm..1e-3 mm
        np.testing.assert_allclose(corner_high - corner_low, size, atol=1e-5)


def test_diameter_matches_models_info(lmo_models, models_info):
    for object_id, model in lmo_models.items():
        # models_info.json gives 3 decimals in millimetres.
        assert mesh.diameter(model.vertices) == pytest.approx(models_info[object_id]["diameter"] / 1000, abs=1e-6)


def test_diameter_equals_brute_force_on_subsamples(lmo_models):
    generator = np.random.default_rng(0)
    for model in lmo_models.values():
        subset = model.vertices[generator.choice(len(model.vertices), 1500, replace=False)]
        assert mesh.diameter(subset) == pytest.approx(pdist(subset).max(), rel=1e-12)
    cloud = generator.normal(size=(3000, 3))
    assert mesh.diameter(cloud) == pytest.approx(pdist(cloud).max(), rel=1e-12)
    planar = np.column_stack([generator.uniform(size=(200, 2)), np.zeros(200)])  # degenerate hull
    assert mesh.diameter(planar) == pytest.approx(pdist(planar).max(), rel=1e-12)
    assert mesh.diameter([[1.0, 2.0, 3.0]]) == 0.0
    assert mesh.diameter([[0, 0, 0], [3.0, 4.0, 0]]) == 5.0


def test_obj_and_glb_load_with_textures(shared_data):
    fuze = mesh.load_mesh(shared_data / "meshes" / "fuze.obj")
    assert len(fuze.faces) == 1000 and fuze.visual.kind == "texture"
    assert fuze.visual.uv.shape == (len(fuze.vertices), 2)
    duck = mesh.load_mesh(shared_data / "meshes" / "Duck.glb")
    assert len(duck.faces) == 4212 and duck.visual.kind == "texture"
    scaled = mesh.load_mesh(shared_data / "meshes" / "Duck.glb", scale=0.01)
    np.testing.assert_allclose(scaled.vertices, duck.vertices * 0.01, rtol=1e-12)


def test_sample_points_on_a_box_are_on_the_surface_and_area_weighted():
    box = trimesh.creation.box(extents=[1.0, 2.0, 4.0])
    points = mesh.sample_points(box, 30000, seed=1)
    assert points.shape == (30000, 3)
    np.testing.assert_array_equal(points, mesh.sample_points(box, 30000, seed=1))
    half = np.array([0.5, 1.0, 2.0])
    on_face = np.isclose(np.abs(points), half, atol=1e-12)
    assert np.all(on_face.any(axis=1)) and np.all(np.abs(points) <= half + 1e-12)
    # Face pairs normal to x, y, z have areas 2*8, 2*4, 2*2 out of 28.
    fractions = on_face.mean(axis=0)
    np.testing.assert_allclose(fractions, [16 / 28, 8 / 28, 4 / 28], atol=0.01)
    with pytest.raises(ValueError, match="count: expected a positive number of points, got 0"):
        mesh.sample_points(box, 0)


def test_bounding_box_corners():
    points = np.array([[0.0, -1.0, 2.0], [1.0, 3.0, -2.0], [0.5, 0.0, 0.0]])
    low, high = mesh.bounding_box(points)
    np.testing.assert_array_equal(low, [0, -1, -2])
    np.testing.assert_array_equal(high, [1, 3, 2])
    corners = mesh.bounding_box_corners(points)
    assert corners.shape == (8, 3) and len({tuple(corner) for corner in corners}) == 8
    np.testing.assert_array_equal(corners.min(axis=0), low)
    np.testing.assert_array_equal(corners.max(axis=0), high)
    with pytest.raises(ValueError, match=r"points: expected at least 1 points of shape \(N, 3\), got 0"):
        mesh.bounding_box(np.zeros((0, 3)))


PLY_HEADER = "ply\nformat ascii 1.0\nelement vertex {count}\nproperty float x\nproperty float y\nproperty float z\n" \
             "element face {faces}\nproperty list uchar int vertex_indices\nend_header\n"


def test_broken_mesh_files_raise_mesh_error(tmp_path):
    with pytest.raises(MeshError, match=r"missing.ply: mesh file not found"):
        mesh.load_mesh(tmp_path / "missing.ply")
    (tmp_path / "model.xyz").write_text("0 0 0\n")
    with pytest.raises(MeshError, match=r"unsupported mesh format '.xyz'"):
        mesh.load_mesh(tmp_path / "model.xyz")
    (tmp_path / "empty.ply").write_text(PLY_HEADER.format(count=0, faces=0))
    with pytest.raises(MeshError, match=r"empty.ply: (mesh is empty|could not read mesh)"):
        mesh.load_mesh(tmp_path / "empty.ply")
    (tmp_path / "nan.ply").write_text(PLY_HEADER.format(count=3, faces=1) + "0 0 0\n1 0 0\nnan 1 0\n3 0 1 2\n")
    with pytest.raises(MeshError, match=r"nan.ply: mesh has NaN or infinite vertex coordinates"):
        mesh.load_mesh(tmp_path / "nan.ply")
    (tmp_path / "garbage.glb").write_bytes(b"glTF" + bytes(range(64)))
    with pytest.raises(MeshError, match=r"garbage.glb: (could not read mesh|mesh is empty)"):
        mesh.load_mesh(tmp_path / "garbage.glb")
    (tmp_path / "points.obj").write_text("v 0 0 0\nv 1 0 0\n")
    with pytest.raises(MeshError, match=r"points.obj: (mesh is empty|could not read mesh)"):
        mesh.load_mesh(tmp_path / "points.obj")
    (tmp_path / "good.ply").write_text(PLY_HEADER.format(count=3, faces=1) + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    assert len(mesh.load_mesh(tmp_path / "good.ply").faces) == 1
    with pytest.raises(MeshError, match=r"good.ply: scale must be a positive finite number, got 0"):
        mesh.load_mesh(tmp_path / "good.ply", scale=0)
    assert issubclass(MeshError, ValueError)


# --- PLY vertices without trimesh -------------------------------------------------------------

def test_ply_vertices_equal_trimesh_vertices_for_ascii_and_binary_bop_models(shared_data):
    for folder in ("models", "models_eval"):  # LM-O: ASCII PLY with normals/colours; binary little-endian
        for path in sorted((shared_data / "bop_lmo" / folder).glob("obj_*.ply")):
            expected = np.asarray(trimesh.load(path, force="mesh", process=False).vertices, dtype=np.float64)
            np.testing.assert_array_equal(mesh.load_ply_vertices(path), expected, err_msg=str(path))


def test_ply_vertices_big_endian_fallback_and_errors(tmp_path):
    vertices = np.array([[0.5, -1.25, 3.0], [1.0, 2.0, -0.125], [4.0, 0.0, 1.5]], dtype=">f4")
    header = ("ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
              "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n")
    face = np.array([3], ">u1").tobytes() + np.array([0, 1, 2], ">i4").tobytes()
    path = tmp_path / "big.ply"
    path.write_bytes(header.encode() + vertices.tobytes() + face)
    np.testing.assert_array_equal(mesh.load_ply_vertices(path), vertices.astype(np.float64))
    written = tmp_path / "trimesh.ply"  # binary little-endian, as trimesh writes it
    trimesh.creation.box((1, 2, 3)).export(written)
    np.testing.assert_array_equal(mesh.load_ply_vertices(written),
                                  np.asarray(trimesh.load(written, process=False).vertices))
    faces_first = tmp_path / "faces_first.ply"  # not the layout read directly: through trimesh
    faces_first.write_text("ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int vertex_indices\n"
                           "element vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
                           "0 0 0\n1 0 0\n0 1 0\n")
    with pytest.raises(MeshError, match="faces_first.ply"):  # trimesh finds no triangles: load_mesh's error
        mesh.load_ply_vertices(faces_first)
    (tmp_path / "text.ply").write_text("solid nothing\n")
    with pytest.raises(MeshError, match="text.ply: not a PLY file"):
        mesh.load_ply_vertices(tmp_path / "text.ply")
    truncated = tmp_path / "truncated.ply"
    truncated.write_bytes(header.encode() + vertices.tobytes()[:20])
    with pytest.raises(MeshError, match="truncated.ply: malformed PLY vertex data"):
        mesh.load_ply_vertices(truncated)
    with pytest.raises(MeshError, match="missing.ply: could not read mesh"):
        mesh.load_ply_vertices(tmp_path / "missing.ply")
