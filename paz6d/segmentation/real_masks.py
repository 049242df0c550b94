"""Ground-truth visible masks for a BOP split that has poses and meshes but no mask files (the LM-O frames
in ``../shared/data``), rendered from the ground-truth poses.

``visible = the object's own pixels where it is the front surface among all annotated objects of the frame``
(a depth test in the renderer, :attr:`renderers.renderer.RenderOutput.visible_masks`). Objects that are
in the scene but not annotated (LM-O's other LineMOD objects, the table clutter) are not modelled, so these
masks can be larger than the truly visible region where such objects occlude; ``scene_gt_info.json`` is
recomputed from the rendered masks (``bbox_visib``, ``bbox_obj``, ``px_count_*``, ``visib_fract``).

Writes a BOP copy of ``root/split`` restricted to the frames whose RGB image exists (``rgb/`` and ``models/``
linked, JSON files filtered, ``mask/`` and ``mask_visib/`` PNGs), readable by
:class:`paz6d.datasets.bop.reader.BOPDataset`. Run it in its own process (it renders with OpenGL, which must
not share a process with TensorFlow)::

    python -m paz6d.segmentation.real_masks ../shared/data/bop_lmo test data/lmo_masks
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

from paz6d.backend.files import load_json_object, write_json_atomically
from paz6d.backend.image import save_image
from paz6d.datasets.bop.reader import BOPDataset, BOPScene
from paz6d.datasets.bop.scene import find_image


def _box_xywh(mask: np.ndarray) -> list[int]:
    if not mask.any():
        return [-1, -1, -1, -1]
    rows, columns = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    return [int(columns[0]), int(rows[0]), int(columns[-1] - columns[0] + 1), int(rows[-1] - rows[0] + 1)]


def write_rendered_masks(root: str | Path, split: str, out: str | Path, progress: bool = True) -> dict:
    """Renders the visible masks of every frame with an RGB image in ``root/split`` into the BOP copy ``out``.

    Returns:
        ``{"images", "instances"}`` written.
    Raises:
        ValueError: missing split/scene files (named by the BOP reader), ``out`` inside ``root``.
    """
    from renderers import Renderer  # here: OpenGL

    root, out = Path(root), Path(out)
    if out.resolve().is_relative_to(root.resolve()):
        raise ValueError(f"out: {out} lies inside the data set {root}; choose a folder outside it")
    dataset = BOPDataset(root, split)
    if dataset.camera is None:
        raise ValueError(f"{root / 'camera.json'}: file not found (the image size comes from it)")
    out.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(root / "camera.json", out / "camera.json")
    if not (out / "models").exists():
        (out / "models").symlink_to((root / "models").resolve(), target_is_directory=True)
    meshes: dict = {}
    images = instances = 0
    with Renderer(dataset.camera.width, dataset.camera.height, antialias="none") as renderer:
        for scene in dataset.scenes:
            folder = out / split / scene.folder.name
            (folder / "mask").mkdir(parents=True, exist_ok=True)
            (folder / "mask_visib").mkdir(parents=True, exist_ok=True)
            if not (folder / "rgb").exists():
                (folder / "rgb").symlink_to((scene.folder / "rgb").resolve(), target_is_directory=True)
            kept = [im_id for im_id in scene.image_ids if find_image(scene.folder / "rgb", im_id) is not None]
            for name in ("scene_gt.json", "scene_camera.json"):
                data = load_json_object(scene.folder / name)
                write_json_atomically(folder / name, {str(im_id): data[str(im_id)] for im_id in kept})
            infos = {}
            for im_id in tqdm(kept, desc=f"rendering masks of scene {scene.scene_id}", disable=not progress):
                poses = scene.ground_truth[im_id]
                for pose in poses:
                    if pose.obj_id not in meshes:
                        meshes[pose.obj_id] = dataset.model(pose.obj_id)
                rendered = renderer.render(scene.cameras[im_id].K, [(meshes[p.obj_id], p.T_model2cam) for p in poses],
                                           rgb=False)
                infos[str(im_id)] = []
                for index, (full, visible) in enumerate(zip(rendered.masks, rendered.visible_masks)):
                    save_image(folder / "mask" / f"{im_id:06d}_{index:06d}.png", full.astype(np.uint8) * 255)
                    save_image(folder / "mask_visib" / f"{im_id:06d}_{index:06d}.png", visible.astype(np.uint8) * 255)
                    count_all, count_visible = int(full.sum()), int(visible.sum())
                    infos[str(im_id)].append({"bbox_obj": _box_xywh(full), "bbox_visib": _box_xywh(visible),
                                              "px_count_all": count_all, "px_count_valid": count_all,
                                              "px_count_visib": count_visible,
                                              "visib_fract": count_visible / count_all if count_all else 0.0})
                    instances += 1
                images += 1
            write_json_atomically(folder / "scene_gt_info.json", infos)
    BOPScene(out / split / scene.folder.name)  # the copy reads back
    return {"images": images, "instances": instances}


def main(argv: list[str] | None = None) -> int:
    """``python -m paz6d.segmentation.real_masks ROOT SPLIT OUT``."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("root", type=Path, help="BOP data set folder")
    parser.add_argument("split", help="split folder (e.g. test)")
    parser.add_argument("out", type=Path, help="folder of the BOP copy with rendered masks")
    args = parser.parse_args(argv)
    print(write_rendered_masks(args.root, args.split, args.out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
