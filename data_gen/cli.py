"""``paz6d generate``: meshes in, BOP-format synthetic data set out.

Cheap to import: rendering libraries load only inside :func:`run`.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def configure(parser: argparse.ArgumentParser) -> None:
    """Adds the ``generate`` arguments."""
    from renderers.renderer import ANTIALIAS_MODES

    parser.add_argument("--mesh", action="append", required=True, type=Path, metavar="PATH",
                        help="mesh file (PLY/OBJ/GLB/GLTF); repeat for several objects. Files named "
                             "obj_XXXXXX keep that BOP object id")
    parser.add_argument("--out", required=True, type=Path, help="output folder (BOP layout)")
    parser.add_argument("--num-images", required=True, type=int)
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--workers", type=int, default=1, help="worker processes (Ray actors with --backend ray)")
    parser.add_argument("--split", default="train")
    parser.add_argument("--scale", type=float, default=1.0,
                        help="mesh units to metres (0.001 for BOP meshes in millimetres)")
    parser.add_argument("--intrinsics", type=float, nargs=4, metavar=("FX", "FY", "CX", "CY"),
                        help="camera intrinsics in pixels (default fx = fy = 0.9 width, centred)")
    parser.add_argument("--objects-per-image", type=int, nargs=2, default=(1, 3), metavar=("MIN", "MAX"))
    parser.add_argument("--distance", type=float, nargs=2, metavar=("MIN", "MAX"),
                        help="object distance range in metres (default from the largest mesh)")
    parser.add_argument("--rotation", choices=("so3", "view-sphere"), default="so3")
    parser.add_argument("--inplane", type=float, default=180.0, help="max in-plane angle (deg), view-sphere")
    parser.add_argument("--elevation", type=float, nargs=2, default=(-90.0, 90.0), metavar=("MIN", "MAX"),
                        help="viewpoint elevation range (deg), view-sphere")
    parser.add_argument("--distractors", type=int, default=2, help="max distractor primitives per image")
    parser.add_argument("--occluder-probability", type=float, default=0.3)
    parser.add_argument("--backgrounds", type=Path, help="folder of background images (default: procedural)")
    parser.add_argument("--light-count", type=int, nargs=2, default=(1, 3), metavar=("MIN", "MAX"))
    parser.add_argument("--color-jitter", type=float, default=0.2)
    parser.add_argument("--blur-probability", type=float, default=0.3)
    parser.add_argument("--noise", type=float, default=4.0, help="max Gaussian noise std (grey levels)")
    parser.add_argument("--depth-scale", type=float, default=0.1, help="BOP depth scale (mm per PNG unit)")
    parser.add_argument("--images-per-scene", type=int, default=1000)
    parser.add_argument("--crop-size", type=int, default=0, help="also write object crops of this size (0: off)")
    parser.add_argument("--symmetries", type=Path, help="JSON {obj_id: {symmetries_discrete/continuous}}")
    parser.add_argument("--rgb-format", choices=("png", "jpg"), default="png",
                        help="rgb images: lossless png or jpg (quality 95, like BOP PBR sets; faster)")
    parser.add_argument("--antialias", choices=ANTIALIAS_MODES, default="edges",
                        help="edges: one single-sample pass, softened object outlines (default); msaa: 4x "
                             "multisampled colour, ~2x slower; none: binary outlines")
    parser.add_argument("--platform", choices=("egl", "osmesa"), help="OpenGL platform (default: auto)")
    parser.add_argument("--backend", choices=("local", "ray"), default="local")
    parser.add_argument("--ray-address", help="Ray cluster address, e.g. ray://head:10001 (default: local Ray)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    """Generates the data set and prints a summary; bad input raises ``ValueError``."""
    from data_gen.config import GenerationConfig
    from data_gen.generator import generate

    config = GenerationConfig(
        meshes=tuple(args.mesh), output=args.out, num_images=args.num_images, width=args.width, height=args.height,
        seed=args.seed, split=args.split, scale=args.scale,
        intrinsics=None if args.intrinsics is None else tuple(args.intrinsics),
        objects_per_image=tuple(args.objects_per_image),
        distance=None if args.distance is None else tuple(args.distance), rotation=args.rotation,
        inplane_degrees=args.inplane, elevation_degrees=tuple(args.elevation), distractors=args.distractors,
        occluder_probability=args.occluder_probability, backgrounds=args.backgrounds,
        light_count=tuple(args.light_count), color_jitter=args.color_jitter,
        blur_probability=args.blur_probability, noise_std=args.noise, depth_scale=args.depth_scale,
        images_per_scene=args.images_per_scene, crop_size=args.crop_size, symmetries=args.symmetries,
        rgb_format=args.rgb_format, antialias=args.antialias, platform=args.platform)
    summary = generate(config, workers=args.workers, backend=args.backend, ray_address=args.ray_address,
                       show_progress=not args.quiet)
    print(f"paz6d generate: {summary.images_total} images in {config.output} "
          f"({summary.images_rendered} rendered, {summary.images_skipped} already done), "
          f"{summary.files_written} files written in {summary.seconds:.1f} s, "
          f"{summary.images_per_second:.2f} images/s")
    return 0
