"""Mesh loading and geometry (PLY/OBJ/GLB/GLTF through trimesh), lengths in metres.

BOP meshes are in millimetres: ``paz6d.datasets.bop.load_model`` loads them in metres (or pass
``scale=0.001``).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from paz6d.backend.checks import as_points

if TYPE_CHECKING:
    import trimesh

MESH_SUFFIXES = (".ply", ".obj", ".glb", ".gltf", ".off", ".stl")
#: Largest vertex coordinate of a loaded mesh (in the units asked for: a kilometre-scale scene in
#: millimetres still fits); beyond it distances between vertices overflow.
MAX_COORDINATE = 1e12


class MeshError(ValueError):
    """A mesh file is missing, unreadable, empty or holds non-finite coordinates."""


def load_mesh(path: str | Path, scale: float = 1.0) -> trimesh.Trimesh:
    """Loads one mesh (scene files are merged) and multiplies its vertices by ``scale``.

    Keeps vertex colours and UV textures. Raises :class:`MeshError` naming the file when it is
    missing, not a supported format, empty, or has NaN/inf vertices.
    """
    path = Path(path)
    if not path.is_file():
        raise MeshError(f"{path}: mesh file not found")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise MeshError(f"{path}: unsupported mesh format {path.suffix!r}; expected one of {MESH_SUFFIXES}")
    if not np.isfinite(scale) or scale <= 0:
        raise MeshError(f"{path}: scale must be a positive finite number, got {scale}")
    import trimesh  # here, not at the top: importing it (with scipy.spatial, networkx) takes ~0.5 s

    try:
        loaded = trimesh.load(str(path), force="mesh", process=False)
    except Exception as error:  # trimesh raises many exception types for broken files
        raise MeshError(f"{path}: could not read mesh ({type(error).__name__}: {error})") from error
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.vertices) == 0 or len(loaded.faces) == 0:
        raise MeshError(f"{path}: mesh is empty (expected vertices and triangle faces)")
    if not np.all(np.isfinite(loaded.vertices)):
        raise MeshError(f"{path}: mesh has NaN or infinite vertex coordinates")
    faces = np.asarray(loaded.faces)
    if faces.min() < 0 or faces.max() >= len(loaded.vertices):
        bad = int(faces.min()) if faces.min() < 0 else int(faces.max())
        raise MeshError(f"{path}: a face refers to vertex {bad}, but the mesh has {len(loaded.vertices)} vertices")
    if scale != 1.0:
        loaded.apply_scale(scale)
    extent = float(np.abs(loaded.vertices).max())
    if not extent <= MAX_COORDINATE:
        raise MeshError(f"{path}: vertex coordinates reach {extent:.3g} after scaling by {scale:g} (at most "
                        f"{MAX_COORDINATE:g} allowed); check the scale")
    return loaded


_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def load_ply_vertices(path: str | Path) -> np.ndarray:
    """The ``(N, 3)`` float64 vertex coordinates of a PLY file, in the file's units, in file order
    (as :func:`load_mesh` with ``process=False`` gives them), read with numpy alone.

    For evaluation, which needs the points and not a mesh: reading a BOP model this way takes
    milliseconds, where importing trimesh takes ~0.5 s. Supports ASCII and binary PLY whose vertex
    element comes first and has no list properties (every BOP model); anything else falls back to
    :func:`load_mesh`. Raises :class:`MeshError` naming the file when it is missing or malformed.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as error:
        raise MeshError(f"{path}: could not read mesh ({error.strerror or error})") from error
    end = data.find(b"end_header")
    header = data[:end].decode("ascii", errors="replace").splitlines() if end >= 0 else []
    if not header or header[0].strip() != "ply":
        raise MeshError(f"{path}: not a PLY file (no 'ply' ... 'end_header' header)")
    body = data.index(b"\n", end) + 1
    words = [line.split() for line in header[1:] if line.split() and line.split()[0] != "comment"]
    formats = [w[1] for w in words if w[0] == "format" and len(w) > 1]
    elements = [index for index, w in enumerate(words) if w[0] == "element"]
    first = words[elements[0]] if elements else []
    properties = words[elements[0] + 1:elements[1] if len(elements) > 1 else len(words)] if elements else []
    names = [w[-1] for w in properties]
    simple = all(w[0] == "property" and len(w) == 3 and w[1] in _PLY_TYPES for w in properties)
    if (len(formats) != 1 or len(first) != 3 or first[1] != "vertex" or not simple
            or not {"x", "y", "z"} <= set(names)):
        return np.asarray(load_mesh(path).vertices, dtype=np.float64)
    try:
        count = int(first[2])
        if formats[0] == "ascii":
            rows = data[body:].split(b"\n", count)[:count]
            table = np.array([row.split() for row in rows], dtype=np.float64).reshape(count, len(names))
            vertices = np.stack([table[:, names.index(axis)].astype(_PLY_TYPES[properties[names.index(axis)][1]])
                                 for axis in "xyz"], axis=1).astype(np.float64)  # as declared, e.g. float32
        elif formats[0] in ("binary_little_endian", "binary_big_endian"):
            order = "<" if formats[0] == "binary_little_endian" else ">"
            dtype = np.dtype([(name, order + _PLY_TYPES[w[1]]) for name, w in zip(names, properties)])
            table = np.frombuffer(data, dtype=dtype, count=count, offset=body)
            vertices = np.stack([table[axis].astype(np.float64) for axis in "xyz"], axis=1)
        else:
            raise ValueError(f"unknown PLY format {formats[0]!r}")
    except ValueError as error:
        raise MeshError(f"{path}: malformed PLY vertex data ({error})") from error
    if len(vertices) == 0 or not np.all(np.isfinite(vertices)):
        raise MeshError(f"{path}: mesh has no vertices or NaN/infinite vertex coordinates")
    return vertices


def diameter(points) -> float:
    """Largest distance between two of the ``(N, 3)`` points (same unit as the points).

    Exact: the farthest pair lies on the convex hull, so only hull vertices are compared
    (falls back to all points for degenerate, e.g. planar, sets).
    """
    points = as_points(points, "points", min_count=1)
    candidates = points
    if len(points) > 4:
        from scipy.spatial import ConvexHull, QhullError  # here: scipy.spatial costs ~0.2 s to import

        try:
            candidates = points[ConvexHull(points).vertices]
        except QhullError:
            candidates = points
    # Squared distances via |a|^2 + |b|^2 - 2 a.b (one matrix product per block), then the
    # near-maximal pairs are re-measured directly so round-off in that identity cannot matter.
    candidates = candidates - candidates.mean(axis=0)
    squared_norms = np.einsum("ij,ij->i", candidates, candidates)
    best = 0.0
    for start in range(0, len(candidates), 1024):
        block = candidates[start:start + 1024]
        squared = squared_norms[start:start + 1024, None] + squared_norms[None, :] - 2.0 * block @ candidates.T
        rows, columns = np.nonzero(squared >= squared.max() * (1.0 - 1e-9) - 1e-300)
        exact = np.sum((block[rows] - candidates[columns]) ** 2, axis=-1)
        best = max(best, float(exact.max()))
    return float(np.sqrt(best))


def sample_points(mesh: trimesh.Trimesh, count: int, seed: int | np.random.Generator | None = None) -> np.ndarray:
    """Samples ``count`` points uniformly on the surface (area-weighted), ``(count, 3)``."""
    if count <= 0:
        raise ValueError(f"count: expected a positive number of points, got {count}")
    generator = np.random.default_rng(seed)
    triangles = mesh.triangles
    areas = mesh.area_faces
    if areas.sum() <= 0:
        raise MeshError("mesh: total surface area is zero, cannot sample points")
    faces = generator.choice(len(triangles), size=count, p=areas / areas.sum())
    u, v = generator.random((2, count))
    flip = u + v > 1
    u, v = np.where(flip, 1 - u, u), np.where(flip, 1 - v, v)
    chosen = triangles[faces]
    return chosen[:, 0] + u[:, None] * (chosen[:, 1] - chosen[:, 0]) + v[:, None] * (chosen[:, 2] - chosen[:, 0])


def bounding_box(points) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned ``(min_corner, max_corner)`` of ``(N, 3)`` points."""
    points = as_points(points, "points")
    return points.min(axis=0), points.max(axis=0)


def bounding_box_corners(points) -> np.ndarray:
    """The 8 corners ``(8, 3)`` of the axis-aligned box of ``points``."""
    low, high = bounding_box(points)
    return np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1]) for z in (low[2], high[2])])
