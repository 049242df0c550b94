"""SSD single-shot object detection (docs/ssd.md): ``model`` (SSD300/SSD512/light builders), ``loss``
(multibox), ``encoding`` (targets, decoding), ``dataset`` (COCO annotations of ``paz6d generate``),
``train`` (``paz6d train ssd``), ``run_dir`` (its files), ``pipeline`` (:class:`DetectSingleShot`) and
``detect`` (``paz6d detect``). Importing this package loads no TensorFlow."""
