"""Household-shaped distractors: bowls, mugs, cups, bottles, plates and books, the clutter that stands
around tabletop objects in real photographs (LM-O's scenes hold a white bowl and a white cup).

The shapes are closed surfaces of revolution (and a box) centred at the origin, with white vertex
colours, so the generator tints them like its primitive distractors (``--neutral-distractors`` makes a
share of them white to grey, the colour that real bowls and cups often have).
"""

from __future__ import annotations

import numpy as np
import trimesh

from paz6d.synthesis.occluders import paint_white

#: Shape sizes relative to the ``size`` passed to :func:`household_library`.
SIZE_FACTORS = (0.5, 0.8, 1.2)
#: Sections around the axis of every surface of revolution.
SECTIONS = 32


def _revolved(profile: list[tuple[float, float]]) -> trimesh.Trimesh:
    """The closed surface made by turning a profile ``[(radius, height), ...]`` (from the axis at the
    bottom, counter-clockwise, back to the axis) about the z axis, centred on its bounding box."""
    mesh = trimesh.creation.revolve(np.asarray(profile, dtype=np.float64), sections=SECTIONS)
    return mesh.apply_translation(-mesh.bounds.mean(axis=0))


def _bowl(side: float) -> trimesh.Trimesh:
    """A hemispherical bowl ``side`` wide and about ``0.45 * side`` high with a ``side / 20`` wall."""
    radius, wall = 0.5 * side, side / 20
    angles = np.linspace(0.0, np.pi / 2, 9)
    outer = [(radius * np.sin(a), radius * 0.9 * (1 - np.cos(a))) for a in angles]
    inner = [((radius - wall) * np.sin(a), wall + (0.9 * radius - wall) * (1 - np.cos(a))) for a in angles[::-1]]
    return _revolved(outer + inner)


def _cup(side: float, handle: bool) -> trimesh.Trimesh:
    """A cup ``side`` high, ``0.7 * side`` wide, open at the top; with a ring handle when ``handle``."""
    radius, height, wall = 0.35 * side, side, side / 20
    cup = _revolved([(0.0, 0.0), (radius, 0.0), (radius, height), (radius - wall, height),
                     (radius - wall, wall), (0.0, wall)])
    if not handle:
        return cup
    ring = trimesh.creation.torus(major_radius=0.25 * side, minor_radius=side / 18, major_sections=24,
                                  minor_sections=12)
    ring.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (1.0, 0.0, 0.0)))
    ring.apply_translation((radius, 0.0, 0.0))
    mesh = trimesh.util.concatenate([cup, ring])
    return mesh.apply_translation(-mesh.bounds.mean(axis=0))


def _bottle(side: float) -> trimesh.Trimesh:
    """A bottle ``side`` high: a body ``0.36 * side`` wide, a shoulder and a narrow neck."""
    radius = 0.18 * side
    return _revolved([(0.0, 0.0), (radius, 0.0), (radius, 0.6 * side), (0.35 * radius, 0.8 * side),
                      (0.35 * radius, side), (0.0, side)])


def _plate(side: float) -> trimesh.Trimesh:
    """A plate ``side`` wide with a raised rim."""
    radius = 0.5 * side
    return _revolved([(0.0, 0.0), (0.6 * radius, 0.0), (radius, 0.1 * radius), (radius, 0.14 * radius),
                      (0.6 * radius, 0.05 * radius), (0.0, 0.05 * radius)])


def household_shapes(side: float) -> list[trimesh.Trimesh]:
    """Six shapes of largest extent about ``side`` metres, centred at the origin: a bowl, a mug, a cup
    without handle, a bottle, a plate and a book-like flat box."""
    if not np.isfinite(side) or side <= 0:
        raise ValueError(f"side: expected a positive size in metres, got {side}")
    return [_bowl(side), _cup(0.8 * side, handle=True), _cup(0.6 * side, handle=False), _bottle(side),
            _plate(side), trimesh.creation.box((side, 0.72 * side, 0.14 * side))]


def household_library(size: float) -> list[trimesh.Trimesh]:
    """Every shape of :func:`household_shapes` at the :data:`SIZE_FACTORS` of ``size`` (metres), with
    white vertex colours (tinted when rendered): ``6 * 3`` meshes."""
    return paint_white([shape for factor in SIZE_FACTORS for shape in household_shapes(size * factor)])
