"""Pipelines over videos, image folders and camera devices: frame sources (:mod:`paz6d.video.frames`),
:class:`~paz6d.video.player.VideoPlayer`, the annotated video (:mod:`paz6d.video.video_file`), the JSON-lines
stream of messages (:mod:`paz6d.video.records`), pose smoothing over time (:mod:`paz6d.video.smoothing`) and
the ``paz6d run`` command (:mod:`paz6d.video.command`).
"""
