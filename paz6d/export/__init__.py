"""``paz6d export``: a run's network as a TensorFlow SavedModel, a TFLite file or an ONNX file, checked
against the Keras model (:mod:`~paz6d.export.command`); the network each method's pipeline runs
(:mod:`~paz6d.export.networks`); the formats and the callables that run exported files in a pipeline
(:mod:`~paz6d.export.formats`)."""
