"""``paz6d demo``: the README's end-to-end jobs (:mod:`~paz6d.demo.command`): the AAE demo, the KeypointNet
demo, and the scoring and reporting they share (:mod:`~paz6d.demo.report`)."""
