"""The methods' model loaders: each reads its own network and refuses another method's (by its outputs),
naming the file, through the one checked reader ``load_keras_model(outputs=...)``."""

from __future__ import annotations

import pytest

from paz6d.backend.files import save_keras_model_atomically
from paz6d.backend.tensorflow_guard import import_keras, load_keras_model
from paz6d.hrnet.model import HRNetError, load_hrnet
from paz6d.keypointnet.model import KeypointNetError, load_keypointnet
from paz6d.probabilistic_keypoints.model import ProbabilisticKeypointsError, load_model
from paz6d.stn.model import STNModelError, load_classifier


def _network(path, names):
    """A tiny model with dict outputs ``names``, saved to ``path``."""
    keras = import_keras()
    inputs = keras.Input((4, 4, 1))
    outputs = {name: keras.layers.Dense(2, name=name)(inputs) for name in names}
    return save_keras_model_atomically(keras.Model(inputs, outputs), path)


LOADERS = [(load_keypointnet, KeypointNetError, ("uv", "depth", "probabilities"), "a KeypointNet"),
           (load_model, ProbabilisticKeypointsError, ("uv", "depth", "probabilities", "cholesky"),
            "a probabilistic KeypointNet"),
           (load_hrnet, HRNetError, ("heatmaps",), "an HRNet"),
           (load_classifier, STNModelError, ("logits", "probabilities", "theta", "crop"), "a classifier")]


@pytest.mark.parametrize("load, error, names, kind", LOADERS, ids=lambda item: getattr(item, "__name__", None))
def test_each_loader_reads_its_network_and_refuses_another_naming_the_file(tmp_path, load, error, names, kind):
    own = _network(tmp_path / "own.keras", names)
    assert sorted(load(own).output) == sorted(names)
    foreign = _network(tmp_path / "foreign.keras", ("something_else",))
    with pytest.raises(error, match=rf"foreign.keras: expected {kind} with outputs .*got \['something_else'\]"):
        load(foreign)


def test_outputs_accept_any_of_several_sets_and_none_accepts_all(tmp_path):
    path = _network(tmp_path / "two.keras", ("a", "b"))
    assert sorted(load_keras_model(path, outputs=(("a",), ("a", "b"))).output) == ["a", "b"]
    assert sorted(load_keras_model(path).output) == ["a", "b"]
    with pytest.raises(ValueError, match=r"two.keras: expected a model with outputs \['a'\] or \['c'\]"):
        load_keras_model(path, outputs=(("a",), ("c",)))
