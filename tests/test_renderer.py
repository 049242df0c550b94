"""Renderer geometry against independent oracles: analytic projection, trimesh ray casting,
OpenCV-convention projection of model vertices, and the other GL platform."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from paz6d.backend import quaternion
from paz6d.backend.camera import transform_and_project
from paz6d.backend.mesh import load_mesh
from paz6d.backend.transform import from_rotation_translation
from renderers import Light, Lighting, Renderer

REPO = Path(__file__).resolve().parents[1]
K_128 = np.array([[150.0, 0.0, 63.3], [0.0, 160.0, 64.6], [0.0, 0.0, 1.0]])


@pytest.fixture(scope="module")
def renderer():
    with Renderer(128, 128) as instance:
        yield instance


@pytest.fixture(scope="module")
def ape(shared_data):
    return load_mesh(shared_data / "bop_lmo" / "models" / "obj_000001.ply", scale=0.001)


def pose(rotation_vector, translation) -> np.ndarray:
    rotation = quaternion.to_rotation_matrix(quaternion.from_rotation_vector(rotation_vector))
    return from_rotation_translation(rotation, translation)


def square(side: float, color=(255, 255, 255)) -> trimesh.Trimesh:
    """Square of ``side`` metres in the model's z = 0 plane, centred at the origin, facing -z
    (towards an OpenCV camera placed on the -z side... i.e. visible from a camera looking along +z)."""
    half = side / 2
    mesh = trimesh.Trimesh(vertices=[[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]],
                           faces=[[0, 2, 1], [0, 3, 2]], process=False)
    mesh.visual.vertex_colors = np.tile(np.append(color, 255), (4, 1)).astype(np.uint8)
    return mesh


def test_square_mask_follows_the_opencv_pixel_centre_rule(renderer):
    mesh = square(0.1)
    T = pose([0.0, 0.0, 0.0], [0.0131, -0.0071, 0.5])
    out = renderer.render(K_128, [(mesh, T)])
    corners = transform_and_project(mesh.vertices, T, K_128)
    (u_min, v_min), (u_max, v_max) = corners.min(axis=0), corners.max(axis=0)
    columns, rows = np.meshgrid(np.arange(128), np.arange(128))
    expected = (columns > u_min) & (columns < u_max) & (rows > v_min) & (rows < v_max)
    # The corners sit at fractional pixels, so no pixel centre is within 0.05 px of an edge.
    assert min(abs(x - round(x)) for x in (u_min, u_max, v_min, v_max)) > 0.05
    np.testing.assert_array_equal(out.masks[0], expected)
    np.testing.assert_array_equal(out.visible_masks[0], expected)
    np.testing.assert_allclose(out.depth[expected], 0.5, atol=1e-5)
    assert np.all(out.depth[~expected] == 0)


def ray_cast_depth(mesh: trimesh.Trimesh, directions: np.ndarray) -> np.ndarray:
    """Nearest z of rays from the origin along ``directions`` (N, 3) hitting ``mesh`` (camera frame),
    by Moller-Trumbore over every triangle; inf where a ray misses."""
    v0, v1, v2 = (mesh.vertices[mesh.faces[:, i]] for i in range(3))
    edge1, edge2 = v1 - v0, v2 - v0
    nearest = np.full(len(directions), np.inf)
    for index, direction in enumerate(directions):
        p = np.cross(direction, edge2)
        determinant = np.einsum("ij,ij->i", edge1, p)
        valid = np.abs(determinant) > 1e-15
        inverse = np.where(valid, 1.0 / np.where(valid, determinant, 1.0), 0.0)
        s = -v0
        u = np.einsum("ij,ij->i", s, p) * inverse
        q = np.cross(s, edge1)
        v = (q @ direction) * inverse
        t = np.einsum("ij,ij->i", edge2, q) * inverse
        hit = valid & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        if hit.any():
            nearest[index] = (t[hit] * direction[2]).min()
    return nearest


def rasterize_silhouette(mesh: trimesh.Trimesh, T: np.ndarray, K: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Software silhouette: pixels whose centre (u, v) = (col, row) lies in a projected triangle."""
    width, height = size
    triangles = transform_and_project(mesh.vertices, T, K)[mesh.faces]
    mask = np.zeros((height, width), dtype=bool)
    for a, b, c in triangles:
        low = np.maximum(np.ceil(np.minimum(np.minimum(a, b), c)), 0).astype(int)
        high = np.minimum(np.floor(np.maximum(np.maximum(a, b), c)), [width - 1, height - 1]).astype(int)
        if np.any(high < low):
            continue
        columns, rows = np.meshgrid(np.arange(low[0], high[0] + 1), np.arange(low[1], high[1] + 1))
        edges = [(b - a, columns - a[0], rows - a[1]), (c - b, columns - b[0], rows - b[1]),
                 (a - c, columns - c[0], rows - c[1])]
        sides = [e[0] * dy - e[1] * dx for e, dx, dy in edges]
        inside = ((sides[0] >= 0) & (sides[1] >= 0) & (sides[2] >= 0)) | \
                 ((sides[0] <= 0) & (sides[1] <= 0) & (sides[2] <= 0))
        mask[rows[inside], columns[inside]] = True
    return mask


def test_projected_vertices_fall_inside_the_mask(renderer, ape):
    generator = np.random.default_rng(0)
    for _ in range(3):
        T = pose(generator.normal(size=3), [generator.uniform(-0.03, 0.03), generator.uniform(-0.03, 0.03), 0.3])
        out = renderer.render(K_128, [(ape, T)], rgb=False)
        pixels = transform_and_project(ape.vertices, T, K_128)
        columns, rows = np.round(pixels).astype(int).T
        # Most vertices land on a mask pixel; outline vertices may round to the pixel just outside.
        assert out.masks[0][rows, columns].mean() > 0.9
        padded = np.pad(out.masks[0], 1)
        near = np.zeros(len(rows), dtype=bool)
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                near |= padded[rows + 1 + dr, columns + 1 + dc]
        assert near.all()


def test_mask_equals_a_software_rasterization(renderer, ape):
    T = pose([0.7, -0.4, 2.0], [0.005, 0.01, 0.3])
    out = renderer.render(K_128, [(ape, T)], rgb=False)
    expected = rasterize_silhouette(ape, T, K_128, (128, 128))
    disagreement = (out.masks[0] != expected).sum()
    assert expected.sum() > 500
    assert disagreement <= 0.005 * expected.sum()  # only pixel centres on an edge (ties) may differ


def test_depth_equals_ray_cast_surface_depth(renderer, ape):
    T = pose([0.4, -1.1, 0.3], [0.01, -0.005, 0.3])
    out = renderer.render(K_128, [(ape, T)], rgb=False)
    posed = ape.copy()
    posed.apply_transform(T)
    mask = out.masks[0]
    interior = mask.copy()
    interior[1:-1, 1:-1] &= mask[:-2, 1:-1] & mask[2:, 1:-1] & mask[1:-1, :-2] & mask[1:-1, 2:]
    rows, columns = np.nonzero(interior)
    pick = np.random.default_rng(1).choice(len(rows), size=min(100, len(rows)), replace=False)
    rows, columns = rows[pick], columns[pick]
    directions = np.stack([(columns - K_128[0, 2]) / K_128[0, 0], (rows - K_128[1, 2]) / K_128[1, 1],
                           np.ones(len(rows))], axis=1)
    nearest = ray_cast_depth(posed, directions)
    assert np.isfinite(nearest).all()
    np.testing.assert_allclose(out.depth[rows, columns], nearest, atol=1e-3)  # the 1 mm requirement
    assert np.median(np.abs(out.depth[rows, columns] - nearest)) < 1e-4


def test_tilted_plane_depth_matches_analytic_intersection(renderer):
    T = pose([0.0, np.radians(55), 0.0], [0.0, 0.0, 0.6])
    out = renderer.render(K_128, [(square(0.5), T)], rgb=False)
    normal, point = T[:3, 2], T[:3, 3]
    rows, columns = np.nonzero(out.depth > 0)
    directions = np.stack([(columns - K_128[0, 2]) / K_128[0, 0], (rows - K_128[1, 2]) / K_128[1, 1],
                           np.ones(len(rows))], axis=1)
    z = (normal @ point) / (directions @ normal)
    np.testing.assert_allclose(out.depth[rows, columns], z, atol=1e-4)


def test_occlusion_gives_visible_and_full_masks(renderer):
    front, back = square(0.04), square(0.1)
    T_front, T_back = pose([0, 0, 0], [0.01, 0.0, 0.4]), pose([0, 0, 0], [0.0, 0.0, 0.5])
    out = renderer.render(K_128, [(back, T_back), (front, T_front)])
    alone_back = renderer.render(K_128, [(back, T_back)]).masks[0]
    alone_front = renderer.render(K_128, [(front, T_front)]).masks[0]
    np.testing.assert_array_equal(out.masks[0], alone_back)
    np.testing.assert_array_equal(out.masks[1], alone_front)
    np.testing.assert_array_equal(out.visible_masks[1], alone_front)
    np.testing.assert_array_equal(out.visible_masks[0], alone_back & ~alone_front)
    np.testing.assert_array_equal(out.visible_masks.any(axis=0), out.depth > 0)
    np.testing.assert_allclose(out.depth[out.visible_masks[1]], 0.4, atol=1e-5)


def test_same_mesh_twice_and_cache_eviction_keep_results_exact(ape):
    small = square(0.03)
    T_a, T_b = pose([0.2, 0.1, 0], [-0.04, 0, 0.5]), pose([0, 0.3, 0.1], [0.04, 0, 0.5])
    with Renderer(96, 96, max_cached_meshes=1) as renderer:
        K = np.array([[120.0, 0, 47.5], [0, 120.0, 47.5], [0, 0, 1]])
        reference = renderer.render(K, [(ape, T_a), (ape, T_b)])
        renderer.render(K, [(small, T_a)])  # evicts the ape from the GPU cache
        again = renderer.render(K, [(ape, T_a), (ape, T_b)])
        single = renderer.render(K, [(ape, T_b)])
    np.testing.assert_array_equal(reference.masks, again.masks)
    np.testing.assert_array_equal(reference.rgb, again.rgb)
    np.testing.assert_array_equal(again.masks[1], single.masks[0])
    assert reference.masks[0].sum() > 50 and not np.array_equal(reference.masks[0], reference.masks[1])


def test_vertex_colours_render_as_themselves_under_unit_ambient(renderer):
    color = (200, 60, 30)
    out = renderer.render(K_128, [(square(0.1, color), pose([0, 0, 0], [0, 0, 0.5]))],
                          lighting=Lighting(ambient=(1.0, 1.0, 1.0), lights=()))
    interior = out.alpha == 255  # edge pixels are anti-aliased against the background
    assert interior.sum() > 0.9 * out.masks[0].sum()
    np.testing.assert_allclose(out.rgb[interior].mean(axis=0), color, atol=1.0)
    np.testing.assert_array_equal(out.rgb[out.alpha == 0], 0)
    partial = (out.alpha > 0) & (out.alpha < 255)
    assert 0 < partial.sum() < 0.2 * out.masks[0].sum()  # anti-aliased outline only


def test_uv_texture_is_mapped_without_flips(tmp_path, renderer):
    texture = np.zeros((64, 64, 3), dtype=np.uint8)
    texture[:32, :32] = (255, 0, 0)   # image top-left: red
    texture[:32, 32:] = (0, 255, 0)   # image top-right: green
    texture[32:, :32] = (0, 0, 255)   # image bottom-left: blue
    texture[32:, 32:] = (255, 255, 0)  # image bottom-right: yellow
    import cv2

    cv2.imwrite(str(tmp_path / "checker.png"), cv2.cvtColor(texture, cv2.COLOR_RGB2BGR))
    (tmp_path / "quad.mtl").write_text("newmtl m\nKa 1 1 1\nKd 1 1 1\nmap_Kd checker.png\n")
    # OpenCV camera: x right, y down. Vertex order: top-left, top-right, bottom-right, bottom-left.
    (tmp_path / "quad.obj").write_text(
        "mtllib quad.mtl\nusemtl m\n"
        "v -0.05 -0.05 0\nv 0.05 -0.05 0\nv 0.05 0.05 0\nv -0.05 0.05 0\n"
        "vt 0 1\nvt 1 1\nvt 1 0\nvt 0 0\n"
        "f 1/1 3/3 2/2\nf 1/1 4/4 3/3\n")
    mesh = load_mesh(tmp_path / "quad.obj")
    out = renderer.render(K_128, [(mesh, pose([0, 0, 0], [0, 0, 0.5]))],
                          lighting=Lighting(ambient=(1.0, 1.0, 1.0), lights=()))
    quarter = 150 * 0.05 / 0.5 / 2  # a quarter of the quad's side, in pixels
    u, v = int(round(K_128[0, 2])), int(round(K_128[1, 2]))
    samples = {(255, 0, 0): (v - quarter, u - quarter), (0, 255, 0): (v - quarter, u + quarter),
               (0, 0, 255): (v + quarter, u - quarter), (255, 255, 0): (v + quarter, u + quarter)}
    for color, (row, column) in samples.items():
        np.testing.assert_allclose(out.rgb[int(row), int(column)], color, atol=6)


def test_textured_obj_and_glb_render_their_textures(shared_data, renderer):
    fuze = load_mesh(shared_data / "meshes" / "fuze.obj")
    duck = load_mesh(shared_data / "meshes" / "Duck.glb", scale=0.05)
    lighting = Lighting(ambient=(1.0, 1.0, 1.0), lights=())
    fuze_out = renderer.render(K_128, [(fuze, pose([np.pi / 2, 0, 0], [0, -0.11, 0.5]))], lighting=lighting)
    duck_out = renderer.render(K_128, [(duck, pose([np.pi, 0, 0], [-0.01, 0.04, 0.25]))], lighting=lighting)
    fuze_pixels = fuze_out.rgb[fuze_out.visible_masks[0]].astype(float)
    duck_pixels = duck_out.rgb[duck_out.visible_masks[0]].astype(float)
    assert len(fuze_pixels) > 300 and len(duck_pixels) > 300
    # The fuze label is multi-coloured (an untextured material renders one flat grey here).
    assert fuze_pixels.std(axis=0).mean() > 20
    # The duck texture is yellow: red and green well above blue.
    red, green, blue = duck_pixels.mean(axis=0)
    assert red > blue + 80 and green > blue + 50


def test_lights_given_per_frame_follow_the_opencv_frame(renderer):
    mesh, T = square(0.2), pose([0, 0, 0], [0, 0, 0.5])
    dark = Lighting(ambient=(0.0, 0.0, 0.0), lights=())
    towards_scene = Lighting(ambient=(0.0, 0.0, 0.0), lights=(Light("directional", direction=(0, 0, 1)),))
    from_behind = Lighting(ambient=(0.0, 0.0, 0.0), lights=(Light("directional", direction=(0, 0, -1)),))
    point_above = Lighting(ambient=(0.0, 0.0, 0.0),
                           lights=(Light("point", intensity=0.5, position=(0.0, -0.2, 0.45)),))
    brightness = {}
    for name, lighting in [("dark", dark), ("front", towards_scene), ("behind", from_behind),
                           ("point", point_above), ("front_again", towards_scene)]:
        out = renderer.render(K_128, [(mesh, T)], lighting=lighting)
        brightness[name] = out.rgb[out.masks[0]].mean()
        if name == "point":
            rows = np.nonzero(out.masks[0].any(axis=1))[0]
            top, bottom = out.rgb[rows[2]].max(), out.rgb[rows[-3]].max()
            assert top > bottom + 20  # light above the camera (-y in OpenCV) lights the image top
    # pyrender clamps n.l to at least 0.001, so a light from behind leaks a few grey levels.
    assert brightness["dark"] == 0 and brightness["behind"] < 12
    assert brightness["front"] > 100 and brightness["front_again"] == brightness["front"]


def test_tints_scale_the_object_colour(renderer):
    mesh, T = square(0.1, (200, 200, 200)), pose([0, 0, 0], [0, 0, 0.5])
    lighting = Lighting(ambient=(1.0, 1.0, 1.0), lights=())
    plain = renderer.render(K_128, [(mesh, T)], lighting=lighting)
    tinted = renderer.render(K_128, [(mesh, T)], lighting=lighting, tints=[[1.0, 0.5, 0.0]])
    plain_color = plain.rgb[plain.masks[0]].mean(axis=0)
    tinted_color = tinted.rgb[tinted.masks[0]].mean(axis=0)
    # Tints act in linear light; the output is gamma-encoded with 1/2.2.
    np.testing.assert_allclose(tinted_color, plain_color * np.array([1.0, 0.5 ** (1 / 2.2), 0.0]), atol=2)
    again = renderer.render(K_128, [(mesh, T)], lighting=lighting)
    np.testing.assert_array_equal(again.rgb, plain.rgb)


def test_skipping_outputs_and_bad_input(renderer, ape):
    T = pose([0, 0, 0], [0, 0, 0.5])
    out = renderer.render(K_128, [(ape, T)], rgb=False, masks=False)
    assert out.rgb is None and out.masks is None and out.visible_masks is None and out.depth.dtype == np.float32
    empty = renderer.render(K_128, [])
    assert empty.masks.shape == (0, 128, 128) and not empty.depth.any()
    with pytest.raises(ValueError, match="K"):
        renderer.render(np.eye(3) * [1, 1, 0], [(ape, T)])
    with pytest.raises(ValueError, match="objects\\[0\\]"):
        renderer.render(K_128, [("not a mesh", T)])
    with pytest.raises(ValueError, match="T_model2cam"):
        renderer.render(K_128, [(ape, np.ones((4, 4)))])
    with pytest.raises(ValueError, match="tints"):
        renderer.render(K_128, [(ape, T)], tints=[[1, 1]])
    with pytest.raises(ValueError, match="width/height"):
        Renderer(0, 10)
    with pytest.raises(ValueError, match="Light.kind"):
        Light("spot")


RENDER_SCRIPT = """
import json, sys
import numpy as np
from paz6d.backend.mesh import load_mesh
from renderers import Renderer
mesh = load_mesh(sys.argv[2], scale=0.001)
poses = np.array(json.loads(sys.argv[3]))
K = np.array([[150.0, 0.0, 63.3], [0.0, 160.0, 64.6], [0.0, 0.0, 1.0]])
with Renderer(128, 128, platform=sys.argv[1]) as renderer:
    out = renderer.render(K, [(mesh, T) for T in poses])
    assert renderer.platform == sys.argv[1]
np.savez(sys.argv[4], masks=out.masks, visible=out.visible_masks, depth=out.depth)
"""


def render_in_subprocess(platform: str, mesh_path: Path, poses: np.ndarray, output: Path):
    environment = dict(os.environ, PYTHONPATH=str(REPO))
    environment.pop("PAZ6D_GL_PLATFORM", None)
    subprocess.run([sys.executable, "-c", RENDER_SCRIPT, platform, str(mesh_path), json.dumps(poses.tolist()),
                    str(output)], check=True, env=environment, cwd=REPO, timeout=120)
    return np.load(output)


def test_osmesa_and_egl_agree(shared_data, tmp_path, renderer, ape):
    poses = np.stack([pose([0.3, 0.2, 1.0], [0.0, 0.0, 0.45]), pose([-1.0, 0.5, 0.2], [0.02, 0.01, 0.5])])
    mesh_path = shared_data / "bop_lmo" / "models" / "obj_000001.ply"
    # One process cannot use both platforms: the other one renders in a subprocess.
    other = {"egl": "osmesa", "osmesa": "egl"}[renderer.platform]
    here = renderer.render(K_128, [(ape, T) for T in poses], rgb=False)
    there = render_in_subprocess(other, mesh_path, poses, tmp_path / f"{other}.npz")
    assert here.masks[0].sum() > 300 and here.visible_masks[1].sum() < here.masks[1].sum()
    for ours, theirs in [(here.masks, there["masks"]), (here.visible_masks, there["visible"])]:
        for a, b in zip(ours, theirs):
            assert (a & b).sum() / (a | b).sum() >= 0.99
    both = (here.depth > 0) & (there["depth"] > 0)
    assert np.median(np.abs(here.depth[both] - there["depth"][both])) < 1e-4


@pytest.mark.parametrize("layout", ["single", "apart", "overlapping"])
def test_single_sample_mode_gives_the_same_depth_and_masks(renderer, ape, layout):
    T_left, T_right = pose([0.3, 0.2, 1.0], [-0.045, 0.0, 0.45]), pose([-1.0, 0.5, 0.2], [0.045, 0.01, 0.5])
    T_behind = pose([-1.0, 0.5, 0.2], [-0.03, 0.0, 0.55])
    objects = {"single": [(ape, T_left)], "apart": [(ape, T_left), (ape, T_right)],
               "overlapping": [(ape, T_left), (ape, T_behind)]}[layout]
    reference = renderer.render(K_128, objects)
    with Renderer(128, 128, antialias="none") as single_sample:
        out = single_sample.render(K_128, objects)
    np.testing.assert_array_equal(out.masks, reference.masks)
    np.testing.assert_array_equal(out.visible_masks, reference.visible_masks)
    np.testing.assert_allclose(out.depth, reference.depth, atol=5e-5)  # colour vs flat shader rounding
    assert set(np.unique(out.alpha)) <= {0, 255}
    if renderer.platform == "egl":
        assert ((reference.alpha > 0) & (reference.alpha < 255)).any()
    if layout == "overlapping":
        assert (out.visible_masks[1] != out.masks[1]).any()


def test_masks_only_for_the_first_objects_with_the_rest_occluding(renderer):
    front, back = square(0.04), square(0.1)
    T_front, T_back = pose([0, 0, 0], [0.01, 0.0, 0.4]), pose([0, 0, 0], [0.0, 0.0, 0.5])
    everything = renderer.render(K_128, [(back, T_back), (front, T_front)])
    first_only = renderer.render(K_128, [(back, T_back), (front, T_front)], masked_objects=1)
    assert first_only.masks.shape == (1, 128, 128)
    np.testing.assert_array_equal(first_only.masks[0], everything.masks[0])
    np.testing.assert_array_equal(first_only.visible_masks[0], everything.visible_masks[0])
    with pytest.raises(ValueError, match="masked_objects"):
        renderer.render(K_128, [(back, T_back)], masked_objects=2)


def exact_coverage(mesh: trimesh.Trimesh, T: np.ndarray, K: np.ndarray, size: tuple[int, int],
                   samples: int = 8) -> np.ndarray:
    """Fraction of each pixel's area covered by the projected mesh (``samples``² sub-pixel points)."""
    width, height = size
    offsets = (np.arange(samples) + 0.5) / samples - 0.5
    total = np.zeros((height, width))
    for dy in offsets:
        for dx in offsets:
            shifted = K.copy()
            shifted[:2, 2] -= (dx, dy)  # the sub-pixel point (u + dx, v + dy) becomes a pixel centre
            total += rasterize_silhouette(mesh, T, shifted, size)
    return total / samples ** 2


@pytest.mark.parametrize("angle, gain", [(0.1, 0.5), (0.37, 0.75)])
def test_edge_antialiasing_estimates_pixel_coverage(angle, gain):
    """Coverage error on the outline's pixels: binary 0.26 / 0.21, edges 0.10 / 0.14, MSAA 0.07 / 0.07
    for edges at 6 / 21 degrees to the pixel grid."""
    mesh = square(0.1, color=(200, 60, 30))
    T = pose([0.0, 0.0, angle], [0.0031, -0.0047, 0.5])
    coverage = exact_coverage(mesh, T, K_128, (128, 128))
    with Renderer(128, 128, antialias="edges") as edges, Renderer(128, 128, antialias="none") as binary:
        soft, hard = edges.render(K_128, [(mesh, T)]), binary.render(K_128, [(mesh, T)])
    np.testing.assert_array_equal(soft.masks, hard.masks)  # annotations stay pixel-centre exact
    np.testing.assert_array_equal(soft.depth, hard.depth)
    band = (coverage > 0) & (coverage < 1)
    soft_error = np.abs(soft.alpha / 255.0 - coverage)[band].mean()
    hard_error = np.abs(hard.alpha / 255.0 - coverage)[band].mean()
    assert soft_error < gain * hard_error, (soft_error, hard_error)
    assert abs(soft.alpha.sum() / 255.0 - coverage.sum()) < 0.01 * coverage.sum()  # area kept
    interior = coverage == 1
    np.testing.assert_array_equal(soft.rgb[interior], hard.rgb[interior])
    near = np.zeros_like(hard.masks[0])
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            near |= np.roll(hard.masks[0], (dy, dx), axis=(0, 1))
    np.testing.assert_array_equal(soft.alpha[~near], 0)  # coverage spreads one pixel at most
    outside_ring = (soft.alpha > 0) & ~hard.masks[0]  # the pixels added outside the binary outline
    assert outside_ring.sum() > 50
    np.testing.assert_array_equal(soft.rgb[outside_ring],
                                  np.broadcast_to(hard.rgb[interior][0], (outside_ring.sum(), 3)))


def test_edge_antialiasing_of_an_axis_aligned_edge():
    from renderers.edge_coverage import soften_silhouette

    rgb = np.zeros((20, 20, 3), dtype=np.uint8)
    alpha = np.zeros((20, 20), dtype=np.uint8)
    rgb[5:15, 5:15], alpha[5:15, 5:15] = (10, 100, 250), 255
    soft_rgb, soft_alpha = soften_silhouette(rgb, alpha)
    assert soft_alpha[10, 5] == 191 and soft_alpha[10, 4] == 64 and soft_alpha[10, 3] == 0  # 3/4, 1/4 on an edge
    assert soft_alpha[10, 10] == 255 and soft_alpha[4, 4] == 16  # 1/16 diagonally off a corner
    np.testing.assert_array_equal(soft_rgb[10, 4], (10, 100, 250))
    np.testing.assert_array_equal(rgb[10, 4], 0)  # inputs untouched
    empty_rgb, empty_alpha = soften_silhouette(np.zeros((4, 4, 3), np.uint8), np.zeros((4, 4), np.uint8))
    assert not empty_alpha.any() and not empty_rgb.any()


def test_unknown_antialias_mode_is_rejected():
    with pytest.raises(ValueError, match="antialias: expected one of"):
        Renderer(16, 16, antialias=True)
