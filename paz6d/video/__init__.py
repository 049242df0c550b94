"""Pipelines over videos, image folders and camera devices: :class:`~paz6d.video.player.VideoPlayer`, the
JSON-lines stream of messages (:mod:`paz6d.video.records`) and the ``paz6d run`` command
(:mod:`paz6d.video.command`). Frames come from :mod:`paz6d.backend.frames`.
"""
