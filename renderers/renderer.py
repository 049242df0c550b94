"""Offscreen renderer (pyrender on EGL or OSMesa) taking OpenCV cameras and poses.

Per frame it makes at most three kinds of pass on one reused GL context:

1. a lit, anti-aliased colour pass (``rgb`` and its coverage ``alpha``);
2. a flat, single-sample instance pass that gives exact pixel-centre depth and the visible masks
   (the colour pass' depth is resolved from one MSAA sample, up to half a pixel off-centre);
3. one instance pass per object whose projected bounding box overlaps another object's, for its
   full (unoccluded) mask; an object that overlaps nothing has full mask == visible mask.

With ``antialias="edges"`` or ``"none"`` (and always on OSMesa, which has no MSAA) the colour
pass is single-sample, so its depth is exact and pass 2 is needed only when boxes overlap;
``"edges"`` then softens the object outlines (:mod:`renderers.edge_coverage`).
"""

from __future__ import annotations

import functools
from collections import OrderedDict
from dataclasses import dataclass
from typing import TYPE_CHECKING, Sequence

import numpy as np

from paz6d.backend.checks import as_camera_matrix
from paz6d.backend.transform import as_pose_matrix
from renderers import conventions
from renderers.antialias import ANTIALIAS_MODES
from renderers.edge_coverage import soften_silhouette
from renderers.lights import Lighting
from renderers.platform import select_platform

if TYPE_CHECKING:  # trimesh costs ~1 s to import; only needed once meshes are rendered
    import trimesh


@dataclass
class RenderOutput:
    """What :meth:`Renderer.render` returns for ``N`` objects on an ``H×W`` image.

    Attributes:
        rgb: ``(H, W, 3)`` uint8, background colour where no object is (``None`` when skipped).
        alpha: ``(H, W)`` uint8 anti-aliased coverage of the colour pass, 255 = object
            (``None`` when the colour pass was skipped); use it to composite over a background.
        depth: ``(H, W)`` float32 z in metres at pixel centres, 0 = background.
        masks: ``(M, H, W)`` bool, each object rendered alone (``None`` when skipped); ``M = N``
            unless ``masked_objects`` asked for fewer.
        visible_masks: ``(M, H, W)`` bool, the pixels where each object is the front surface
            (``None`` when skipped).
    """

    rgb: np.ndarray | None
    alpha: np.ndarray | None
    depth: np.ndarray
    masks: np.ndarray | None
    visible_masks: np.ndarray | None


def _as_mesh(mesh, index: int) -> "trimesh.Trimesh":
    import trimesh

    if not isinstance(mesh, trimesh.Trimesh):
        raise ValueError(f"objects[{index}]: expected a trimesh.Trimesh, got {type(mesh).__name__}")
    if len(mesh.faces) == 0:
        raise ValueError(f"objects[{index}]: mesh has no faces")
    return mesh


def _instance_color(index: int) -> np.ndarray:
    """Unique 24-bit RGB code of instance ``index`` (0-based); black stays background."""
    code = index + 1
    return np.array([(code >> 16) & 255, (code >> 8) & 255, code & 255], dtype=np.float64)


def _decode_instances(color: np.ndarray) -> np.ndarray:
    """Inverse of :func:`_instance_color` for an ``(H, W, 3)`` uint8 image: ``(H, W)`` int, -1 = none."""
    color = color.astype(np.int32)
    return (color[..., 0] << 16 | color[..., 1] << 8 | color[..., 2]) - 1


def _gamma_to_linear(color: np.ndarray) -> np.ndarray:
    """Gamma-2.2 encoded values in [0, 1] to linear light (pyrender encodes its output with 1/2.2)."""
    return color ** 2.2


def _to_pyrender_mesh(pyrender, mesh: trimesh.Trimesh):
    """pyrender mesh of ``mesh``; vertex colours are linearized (gamma 2.2, the inverse of
    pyrender's output encoding) so a vertex colour renders as itself under unit white ambient."""
    gpu_mesh = pyrender.Mesh.from_trimesh(mesh)
    for primitive in gpu_mesh.primitives:
        if primitive.color_0 is not None:
            colors = np.array(primitive.color_0, dtype=np.float64)
            colors[:, :3] = _gamma_to_linear(colors[:, :3])
            primitive.color_0 = colors.astype(np.float32)
    return gpu_mesh


def _checked_material(material, index: int) -> tuple[float, float] | None:
    """``materials[index]`` of :meth:`Renderer.render` as ``(roughness, metallic)`` floats, or None."""
    if material is None:
        return None
    values = np.asarray(material, dtype=np.float64) if np.shape(material) == (2,) else None
    if values is None or not np.all((values >= 0) & (values <= 1)):
        raise ValueError(f"materials[{index}]: expected None or (roughness, metallic) in [0, 1], got {material!r}")
    return float(values[0]), float(values[1])


def _destroy_only_own_egl_context(platform) -> None:
    """Makes closing one renderer leave the others working.

    pyrender's EGL platform calls ``eglTerminate`` on close, which invalidates every context on
    the (per-process) EGL display; this replaces that with destroying only its own context.
    """
    from OpenGL import EGL

    def delete_context() -> None:
        if platform._egl_context is not None:
            EGL.eglMakeCurrent(platform._egl_display, EGL.EGL_NO_SURFACE, EGL.EGL_NO_SURFACE, EGL.EGL_NO_CONTEXT)
            EGL.eglDestroyContext(platform._egl_display, platform._egl_context)
            platform._egl_context = None
        platform._egl_display = None

    platform.delete_context = delete_context


def _single_sample_framebuffer(offscreen, scene) -> None:
    """Turns pyrender's 4× multisampled offscreen framebuffer into a single-sample one.

    pyrender allocates it (with 4 samples, not configurable) on the first render; respecifying
    the two renderbuffers' storage with 0 samples keeps the framebuffer and its blits valid.
    """
    import pyrender
    from OpenGL import GL

    offscreen.render(scene, flags=pyrender.RenderFlags.DEPTH_ONLY)  # allocates the framebuffer
    renderer = offscreen._renderer
    offscreen._platform.make_current()
    buffers = ((renderer._main_cb_ms, GL.GL_RGBA), (renderer._main_db_ms, GL.GL_DEPTH_COMPONENT24))
    for renderbuffer, storage in buffers:
        GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, renderbuffer)
        GL.glRenderbufferStorageMultisample(GL.GL_RENDERBUFFER, 0, storage, offscreen.viewport_width,
                                            offscreen.viewport_height)
    GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, 0)


class Renderer:
    """Renders meshes posed in the OpenCV camera frame; one GL context reused for every frame.

    Args:
        width: image width in pixels.
        height: image height in pixels.
        platform: ``"egl"``, ``"osmesa"`` or ``None`` (auto: env ``PAZ6D_GL_PLATFORM``, else
            EGL if it works, else OSMesa); see :func:`renderers.platform.select_platform`.
        znear: near clipping distance in metres.
        zfar: far clipping distance in metres.
        max_cached_meshes: GPU copies kept for this many distinct meshes (least recently used
            ones are freed).
        background: RGB uint8 colour of pixels with no object in ``rgb``.
        antialias: ``"msaa"``: 4× multisampled colour pass (EGL only; on OSMesa, which never
            multisamples, the same as ``"none"``). ``"edges"``: single-sample pass whose object
            outlines get fractional coverage (:func:`renderers.edge_coverage.soften_silhouette`).
            ``"none"``: single-sample, binary coverage. The single-sample modes get colour,
            exact depth and, when no two objects' boxes overlap, the masks from one pass: about
            twice as fast on llvmpipe, which shades every sample of a multisampled pass.

    Example:
        >>> with Renderer(640, 480) as renderer:                                  # doctest: +SKIP
        ...     out = renderer.render(K, [(mesh, T_model2cam)])
    """

    def __init__(self, width: int, height: int, platform: str | None = None, znear: float = 0.01,
                 zfar: float = 100.0, max_cached_meshes: int = 64, background=(0, 0, 0),
                 antialias: str = "msaa"):
        if int(width) != width or int(height) != height or width <= 0 or height <= 0:
            raise ValueError(f"width/height: expected positive integer pixel sizes, got {width}x{height}")
        if not 0 < znear < zfar:
            raise ValueError(f"znear/zfar: expected 0 < znear < zfar (metres), got {znear}, {zfar}")
        if max_cached_meshes < 1:
            raise ValueError(f"max_cached_meshes: expected >= 1, got {max_cached_meshes}")
        if antialias not in ANTIALIAS_MODES:
            raise ValueError(f"antialias: expected one of {ANTIALIAS_MODES}, got {antialias!r}")
        background = np.asarray(background, dtype=np.float64)
        if background.shape != (3,) or np.any(background < 0) or np.any(background > 255):
            raise ValueError(f"background: expected 3 values in [0, 255], got {background.tolist()}")
        self.width, self.height = int(width), int(height)
        self.znear, self.zfar = float(znear), float(zfar)
        self.platform = select_platform(platform)
        import pyrender  # only after the platform is chosen

        self._pyrender = pyrender
        self._max_cached_meshes = int(max_cached_meshes)
        self._scene = pyrender.Scene(bg_color=np.append(background / 255.0, 0.0), ambient_light=np.zeros(3))
        self._camera = _projection_camera_class()(self.width, self.height, self.znear, self.zfar)
        self._scene.add(self._camera, pose=np.eye(4))
        self._meshes: OrderedDict[int, tuple[trimesh.Trimesh, object, list]] = OrderedDict()
        self._light_nodes: list = []
        self._lighting: Lighting | None = None
        self._offscreen = pyrender.OffscreenRenderer(self.width, self.height)
        self._antialias = antialias
        self._multisampled = self.platform == "egl" and antialias == "msaa"
        if self.platform == "egl":
            _destroy_only_own_egl_context(self._offscreen._platform)
            if not self._multisampled:
                _single_sample_framebuffer(self._offscreen, self._scene)

    # -- lifetime -------------------------------------------------------------------------
    def close(self) -> None:
        """Frees the GL context and every GPU buffer (idempotent)."""
        if getattr(self, "_offscreen", None) is not None:
            self._offscreen.delete()
            self._offscreen = None
            self._meshes.clear()

    def __enter__(self) -> "Renderer":
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:  # interpreter shutdown: GL may already be gone
            pass

    # -- scene management -----------------------------------------------------------------
    def _gpu_mesh(self, mesh: trimesh.Trimesh):
        """Cached pyrender mesh and node pool for ``mesh`` (LRU, keyed by object identity)."""
        key = id(mesh)
        entry = self._meshes.get(key)
        if entry is None or entry[0] is not mesh:
            entry = (mesh, _to_pyrender_mesh(self._pyrender, mesh), [])
            self._meshes[key] = entry
            while len(self._meshes) > self._max_cached_meshes:
                _, (_, _, nodes) = self._meshes.popitem(last=False)
                for node in nodes:  # pyrender frees GPU buffers of meshes that leave the scene
                    self._scene.remove_node(node)
        self._meshes.move_to_end(key)
        return entry

    def _place_objects(self, objects, tints, materials) -> list:
        """Poses one scene node per object; hides cached meshes not in this frame."""
        used: dict[int, int] = {}
        nodes = []
        for (mesh, T_model2cam), tint, material in zip(objects, tints, materials):
            mesh_key = id(mesh)
            _, gpu_mesh, pool = self._gpu_mesh(mesh)
            slot = used.get(mesh_key, 0)
            used[mesh_key] = slot + 1
            pose = conventions.opengl_transform_from_model2cam(T_model2cam)
            if slot < len(pool):
                self._scene.set_pose(pool[slot], pose)
            else:
                pool.append(self._scene.add(gpu_mesh, pose=pose))
            nodes.append(pool[slot])
            gpu_mesh.is_visible = True
            for primitive in gpu_mesh.primitives:
                own = getattr(primitive, "_paz6d_own_material", None)
                if own is None:  # the mesh's own factors, before any tint or material of a frame
                    own = (np.array(primitive.material.baseColorFactor, dtype=np.float64),
                           primitive.material.roughnessFactor, primitive.material.metallicFactor)
                    primitive._paz6d_own_material = own
                base, roughness, metallic = own
                factor = base.copy()
                factor[:3] *= tint
                primitive.material.baseColorFactor = factor
                if material is not None:
                    roughness, metallic = material
                primitive.material.roughnessFactor, primitive.material.metallicFactor = roughness, metallic
        for key, (_, gpu_mesh, pool) in self._meshes.items():
            count = used.get(key, 0)
            # Keep one node per cached mesh in the scene so pyrender keeps its GPU buffers.
            while len(pool) > max(count, 1):
                self._scene.remove_node(pool.pop())
            if count == 0:
                gpu_mesh.is_visible = False
        return nodes

    def _set_lighting(self, lighting: Lighting) -> None:
        if lighting == self._lighting:
            return
        for node in self._light_nodes:
            self._scene.remove_node(node)
        self._light_nodes = []
        self._scene.ambient_light = np.asarray(lighting.ambient, dtype=np.float64)
        for light in lighting.lights:
            if light.kind == "directional":
                gl_light = self._pyrender.DirectionalLight(color=light.color, intensity=light.intensity)
            else:
                gl_light = self._pyrender.PointLight(color=light.color, intensity=light.intensity)
            pose = conventions.opengl_transform_from_emitter2cam(light.pose())
            self._light_nodes.append(self._scene.add(gl_light, pose=pose))
        self._lighting = lighting

    # -- rendering ------------------------------------------------------------------------
    def _instance_pass(self, nodes, indices) -> tuple[np.ndarray, np.ndarray]:
        """Flat single-sample pass of ``nodes[indices]``: ``(H, W)`` instance ids and depth."""
        flags = self._pyrender.RenderFlags.SEG
        node_map = {nodes[index]: _instance_color(index) for index in indices}
        color, depth = self._offscreen.render(self._scene, flags=flags, seg_node_map=node_map)
        return _decode_instances(color), depth

    def _projected_boxes(self, K, objects) -> np.ndarray:
        """``(N, 4)`` conservative pixel boxes ``(u_min, v_min, u_max, v_max)`` of each object's
        projected 3D bounding box (1 px margin); NaN rows for objects reaching the near plane."""
        from paz6d.backend.mesh import bounding_box_corners

        boxes = np.full((len(objects), 4), np.nan)
        for index, (mesh, T) in enumerate(objects):
            corners = bounding_box_corners(mesh.bounds) @ T[:3, :3].T + T[:3, 3]
            if np.all(corners[:, 2] > self.znear):
                pixels = corners[:, :2] / corners[:, 2:3] @ K[:2, :2].T + K[:2, 2]
                boxes[index] = [*(pixels.min(axis=0) - 1), *(pixels.max(axis=0) + 1)]
        return boxes

    @staticmethod
    def _overlapping(boxes: np.ndarray) -> np.ndarray:
        """``(N,)`` bool: the box meets another object's box (NaN boxes meet everything)."""
        count = len(boxes)
        unbounded = np.isnan(boxes).any(axis=1)
        overlapping = unbounded & (count > 1)
        for i in range(count):
            for j in range(i + 1, count):
                if unbounded[i] or unbounded[j] or (
                        boxes[i, 0] < boxes[j, 2] and boxes[j, 0] < boxes[i, 2]
                        and boxes[i, 1] < boxes[j, 3] and boxes[j, 1] < boxes[i, 3]):
                    overlapping[i] = overlapping[j] = True
        return overlapping

    def _masks_from_depth(self, depth: np.ndarray, boxes: np.ndarray) -> np.ndarray:
        """Visible masks when no two boxes overlap: each foreground pixel lies in one box only."""
        masks = np.zeros((len(boxes),) + depth.shape, dtype=bool)
        foreground = depth > 0
        for index, box in enumerate(boxes):
            if np.isnan(box).any():  # only possible for a single object: it owns every pixel
                masks[index] = foreground
                continue
            u_min, v_min = max(int(np.floor(box[0])), 0), max(int(np.floor(box[1])), 0)
            u_max, v_max = int(np.ceil(box[2])) + 1, int(np.ceil(box[3])) + 1
            masks[index, v_min:v_max, u_min:u_max] = foreground[v_min:v_max, u_min:u_max]
        return masks

    def render(self, K, objects: Sequence[tuple[trimesh.Trimesh, np.ndarray]], lighting: Lighting | None = None,
               tints=None, rgb: bool = True, masks: bool = True, masked_objects: int | None = None,
               materials=None) -> RenderOutput:
        """Renders ``objects`` seen by a pinhole camera ``K``.

        Args:
            K: ``(3, 3)`` OpenCV intrinsics for this renderer's ``width×height``.
            objects: ``(mesh, T_model2cam)`` pairs, mesh vertices in metres, ``T_model2cam``
                ``(4, 4)`` in the OpenCV camera frame (metres).
            lighting: ambient + lights for this frame (default :class:`Lighting()`).
            tints: ``(N, 3)`` multiplicative RGB factors on each object's base colour (default 1).
            rgb: make the colour pass (``False``: depth and masks only).
            masks: compute ``masks`` and ``visible_masks``.
            masked_objects: masks only for ``objects[:masked_objects]`` (default: all); the
                other objects (distractors, occluders) still occlude them.
            materials: per object ``(roughness, metallic)`` in [0, 1] of its metallic-roughness material
                (0: mirror-like / dielectric), or None for the mesh's own (pyrender's 0.8 / 0.2 for vertex
                colours); default: every mesh's own.

        Returns:
            :class:`RenderOutput`.
        """
        if getattr(self, "_offscreen", None) is None:
            raise ValueError("renderer: already closed")
        K = as_camera_matrix(K)
        objects = [(_as_mesh(mesh, index), as_pose_matrix(T, f"objects[{index}] T_model2cam"))
                   for index, (mesh, T) in enumerate(objects)]
        count = len(objects)
        masked = count if masked_objects is None else int(masked_objects)
        if not 0 <= masked <= count:
            raise ValueError(f"masked_objects: expected 0..{count}, got {masked_objects}")
        tints = np.ones((count, 3)) if tints is None else np.asarray(tints, dtype=np.float64)
        if tints.shape != (count, 3) or not np.all(np.isfinite(tints)) or np.any(tints < 0):
            raise ValueError(f"tints: expected ({count}, 3) non-negative finite factors, got shape {tints.shape}")
        materials = [None] * count if materials is None else [_checked_material(material, index)
                                                              for index, material in enumerate(materials)]
        if len(materials) != count:
            raise ValueError(f"materials: expected {count} entries (one per object), got {len(materials)}")
        self._camera.set_intrinsics(K)
        nodes = self._place_objects(objects, tints, materials)
        self._set_lighting(lighting if lighting is not None else Lighting())

        color_image = alpha = depth = instances = None
        if rgb:
            color, color_depth = self._offscreen.render(self._scene, flags=self._pyrender.RenderFlags.RGBA)
            color_image = np.ascontiguousarray(color[..., :3])
            if color.shape[-1] == 4:
                alpha = np.ascontiguousarray(color[..., 3])
            if not self._multisampled:  # single-sample depth is taken at pixel centres: exact
                depth = color_depth
        boxes = self._projected_boxes(K, objects) if masks else None
        overlapping = self._overlapping(boxes)[:masked] if masks else np.zeros(0, dtype=bool)
        if depth is None or overlapping.any():
            instances, instance_depth = self._instance_pass(nodes, range(count))
            depth = instance_depth if depth is None else depth
        if rgb and alpha is None:  # OSMesa reads back RGB only; it has no MSAA, so coverage is binary
            alpha = np.where(depth > 0, 255, 0).astype(np.uint8)
        if rgb and self._antialias == "edges":
            color_image, alpha = soften_silhouette(color_image, alpha)
        full_masks = visible_masks = None
        if masks:
            if instances is None:
                visible_masks = self._masks_from_depth(depth, boxes[:masked])
            else:
                visible_masks = instances[None] == np.arange(masked)[:, None, None]
            full_masks = visible_masks.copy()
            for index in np.flatnonzero(overlapping):
                alone, _ = self._instance_pass(nodes, [index])
                full_masks[index] = alone == index
        return RenderOutput(color_image, alpha, depth.astype(np.float32, copy=False), full_masks, visible_masks)


@functools.cache
def _projection_camera_class():
    """pyrender camera class taking an OpenCV ``K`` (built lazily: pyrender is imported only
    after the platform is chosen)."""
    import pyrender

    class ProjectionCamera(pyrender.camera.Camera):
        """pyrender camera whose projection comes from an OpenCV ``K`` (skew supported)."""

        def __init__(self, width: int, height: int, znear: float, zfar: float):
            super().__init__(znear=znear, zfar=zfar)
            self._size = (width, height)
            self.set_intrinsics(np.array([[width, 0.0, width / 2], [0.0, width, height / 2], [0.0, 0.0, 1.0]]))

        def set_intrinsics(self, K: np.ndarray) -> None:
            self._projection = conventions.projection_matrix(K, *self._size, self.znear, self.zfar)

        def get_projection_matrix(self, width=None, height=None):
            return self._projection

    return ProjectionCamera
