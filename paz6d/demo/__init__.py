"""``paz6d demo``: the README's end-to-end jobs (AAE; ``--keypoints`` adds KeypointNet)."""
