"""Out-of-distribution test views of one object for the demo's OOD check (:mod:`paz6d.demo.ood_check`).

:func:`render_ood_views` renders ``count`` held-out views (whole camera images, the object alone; view
``i`` draws its pose and its ``"key-fill"`` lights from ``numpy.random.default_rng([seed, i])`` exactly
like :func:`paz6d.keypointnet.views.render_test_images`) twice: under those lights and under
:func:`ood_lighting`, a light set-up no training pipeline renders with. :meth:`OODViews.images`
composites them over the background of a condition of :data:`CONDITIONS`:

=================  ============================================================================
``in-distribution``  the model's own training background style (the reference)
``flat``             one uniform random colour (:func:`~paz6d.synthesis.backgrounds.ood_background`)
``pixel-noise``      every pixel and channel uniform in 0-255
``smooth-field``     per-channel Gaussian-filtered white noise (sigma 4-16 px)
``lighting``         the in-distribution background (same draws) behind the :func:`ood_lighting` render
=================  ============================================================================

The background of view ``i`` under condition ``c`` is drawn from ``default_rng([seed, c, i])`` (``c``
the condition's index; ``lighting`` uses the in-distribution draws so that only the light changes):
the same seed gives the same images for any number of workers. Object pixels (full coverage) are
the rendering's, untouched. Imports neither TensorFlow nor pyrender at import time.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from paz6d.backend import image as image_backend
from paz6d.backend.camera import Camera
from paz6d.backend.mesh import diameter, load_mesh
from paz6d.synthesis.backgrounds import BACKGROUND_STYLES, OOD_BACKGROUND_STYLES, ood_background, procedural_background
from paz6d.synthesis.lighting import random_lighting
from paz6d.synthesis.sampling import hull_points
from paz6d.synthesis.workers import chunks, progress_bar, run_in_workers
from renderers.lights import Light, Lighting

IN_DISTRIBUTION = "in-distribution"
#: The reference first, then the out-of-distribution conditions.
CONDITIONS = (IN_DISTRIBUTION, *OOD_BACKGROUND_STYLES, "lighting")


def ood_lighting(generator: np.random.Generator) -> Lighting:
    """A "top and bounce" set-up: a cool-white directional key light from above and partly from
    behind the object (travelling down and towards the camera), a dim warm directional bounce light
    from below, low grey ambient and no light at the camera. The training set-ups differ: KeypointNet's
    ``"key-fill"`` and ``paz6d generate``'s ``"scene"`` lights always travel into the scene from the
    camera's side (``z > 0.3``), KeypointNet adds a point light at the camera, the AAE renders with the
    default key + camera fill and re-lights in image space."""
    ambient = float(generator.uniform(0.15, 0.3))
    key = (generator.uniform(-0.3, 0.3), 1.0, generator.uniform(-0.6, -0.1))  # OpenCV frame: +y is down
    bounce = (generator.uniform(-0.3, 0.3), -1.0, generator.uniform(0.0, 0.4))
    return Lighting(ambient=(ambient, ambient, ambient),
                    lights=(Light("directional", color=(0.85, 0.92, 1.0), intensity=float(generator.uniform(2.5, 4.0)),
                                  direction=key),
                            Light("directional", color=(1.0, 0.8, 0.6), intensity=float(generator.uniform(0.6, 1.2)),
                                  direction=bounce)))


@dataclass
class OODViews:
    """Renderings of the held-out views (``V`` views, ``H×W`` images).

    Attributes:
        rgb: ``(V, H, W, 3)`` uint8 renderings on black under the training-like ``"key-fill"`` lights.
        relit: ``(V, H, W, 3)`` uint8 renderings on black under :func:`ood_lighting`.
        alpha: ``(V, H, W)`` uint8 anti-aliased coverage (the same under both lights).
        masks: ``(V, H, W)`` bool silhouettes; boxes: ``(V, 4)`` silhouette boxes ``xyxy`` (pixels).
        T_model2cam: ``(V, 4, 4)`` poses (metres).
        seed: the seed of the views and their backgrounds.
    """

    rgb: np.ndarray
    relit: np.ndarray
    alpha: np.ndarray
    masks: np.ndarray
    boxes: np.ndarray
    T_model2cam: np.ndarray
    seed: int

    def __len__(self) -> int:
        return len(self.rgb)

    def backgrounds(self, condition: str, in_distribution_style: str) -> np.ndarray:
        """``(V, H, W, 3)`` uint8 backgrounds of ``condition`` (:data:`CONDITIONS`);
        ``in_distribution_style`` is the model's training style
        (:data:`~paz6d.synthesis.backgrounds.BACKGROUND_STYLES`)."""
        if condition not in CONDITIONS:
            raise ValueError(f"condition: expected one of {CONDITIONS}, got {condition!r}")
        if in_distribution_style not in BACKGROUND_STYLES:
            raise ValueError(f"in_distribution_style: expected one of {BACKGROUND_STYLES}, "
                             f"got {in_distribution_style!r}")
        height, width = self.alpha.shape[1:]
        drawn = IN_DISTRIBUTION if condition == "lighting" else condition
        number = CONDITIONS.index(drawn)
        backgrounds = np.empty_like(self.rgb)
        for index in range(len(self)):
            generator = np.random.default_rng([self.seed, number, index])
            backgrounds[index] = (procedural_background(generator, width, height, in_distribution_style)
                                  if drawn == IN_DISTRIBUTION else ood_background(generator, width, height, drawn))
        return backgrounds

    def images(self, condition: str, in_distribution_style: str) -> np.ndarray:
        """``(V, H, W, 3)`` uint8 test images of ``condition``: the rendering (:attr:`relit` for
        ``"lighting"``, else :attr:`rgb`) alpha-blended over :meth:`backgrounds`."""
        backgrounds = self.backgrounds(condition, in_distribution_style)
        renders = self.relit if condition == "lighting" else self.rgb
        return np.stack([image_backend.alpha_blend(render, alpha, background)
                         for render, alpha, background in zip(renders, self.alpha, backgrounds)])


class _OODRenderer:
    """Render-worker state: the mesh, its hull and diameter, one renderer of the camera's size."""

    def __init__(self, mesh_path: str, mesh_scale: float, camera: Camera):
        from renderers import Renderer

        self.mesh = load_mesh(mesh_path, mesh_scale)
        vertices = np.asarray(self.mesh.vertices)
        self.hull, self.diameter = hull_points(vertices), diameter(vertices)
        self.renderer = Renderer(camera.width, camera.height)

    def close(self) -> None:
        self.renderer.close()


def _render_views(state: _OODRenderer, job: tuple) -> dict[str, np.ndarray]:
    from paz6d.keypointnet.views import sample_pose

    indices, seed, sampling = job
    out: dict[str, list] = {"rgb": [], "relit": [], "alpha": [], "masks": [], "boxes": [], "T_model2cam": []}
    for index in indices:
        generator = np.random.default_rng([seed, index])
        T = sample_pose(generator, state.hull, state.diameter, sampling)
        rendered = state.renderer.render(sampling.camera.K, [(state.mesh, T)],
                                         lighting=random_lighting(generator, "key-fill"))
        if not rendered.masks[0].any():
            raise ValueError(f"view {index}: the object is not visible (empty mask)")
        relit = state.renderer.render(sampling.camera.K, [(state.mesh, T)], masks=False,
                                      lighting=ood_lighting(np.random.default_rng([seed, index, 1])))
        for key, value in (("rgb", rendered.rgb), ("relit", relit.rgb), ("alpha", rendered.alpha),
                           ("masks", rendered.masks[0]), ("boxes", image_backend.mask_box(rendered.masks[0])),
                           ("T_model2cam", T)):
            out[key].append(value)
    return {key: np.stack(values) for key, values in out.items()}


def render_ood_views(mesh_path: str | Path, count: int, seed: int, sampling=None, mesh_scale: float = 1.0,
                     workers: int = 2, chunk: int = 25, progress: bool = True) -> OODViews:
    """Renders ``count`` views (see the module docstring) in ``workers`` spawn processes (0: here).

    Args:
        mesh_path: the object mesh; ``mesh_scale`` converts its units to metres.
        sampling: a :class:`~paz6d.keypointnet.views.ViewSampling` (camera, distances; default one).
    """
    from paz6d.keypointnet.views import ViewSampling

    sampling = ViewSampling() if sampling is None else sampling
    if int(count) <= 0:
        raise ValueError(f"count: expected a positive number of views, got {count}")
    mesh_path = Path(mesh_path)
    if not mesh_path.is_file():
        raise ValueError(f"{mesh_path}: mesh file not found")
    jobs = [(indices, int(seed), sampling) for indices in chunks(list(range(int(count))), chunk)]
    with progress_bar(int(count), "render OOD views", "view", progress) as bar:
        parts = run_in_workers(_OODRenderer, (str(mesh_path), mesh_scale, sampling.camera), _render_views, jobs,
                               max(0, int(workers)), bar, task_size=lambda job: len(job[0]))
    return OODViews(**{key: np.concatenate([part[key] for part in parts]) for key in parts[0]}, seed=int(seed))
