"""Regression: Mesa llvmpipe rendering and TensorFlow/Keras in one process.

TensorFlow must be imported through the guard *before* any GL context exists in the process,
so it is imported here at module level: pytest collects (imports) every test module before it
runs any test, so this holds even when renderer tests run earlier in the same session.
"""

from __future__ import annotations

import numpy as np
import trimesh

from paz6d.backend.tensorflow_guard import import_keras, import_tensorflow

import_tensorflow()  # loads TF's LLVM with RTLD_LOCAL so Mesa's llvmpipe keeps its own

from renderers import Renderer  # noqa: E402  (after TensorFlow on purpose)


def test_render_and_run_keras_in_the_same_process():
    keras = import_keras()
    K = np.array([[60.0, 0, 15.5], [0, 60.0, 15.5], [0, 0, 1]])
    T = np.eye(4)
    T[2, 3] = 0.3
    sphere = trimesh.creation.icosphere(radius=0.05)
    with Renderer(32, 32) as renderer:
        before = renderer.render(K, [(sphere, T)])
        model = keras.Sequential([keras.Input((32, 32, 3)), keras.layers.Conv2D(2, 3),
                                  keras.layers.GlobalAveragePooling2D(), keras.layers.Dense(1)])
        model.compile(optimizer="sgd", loss="mse")
        images = before.rgb[None].astype("float32") / 255.0
        model.fit(images, np.ones((1, 1)), epochs=1, verbose=0)
        prediction = model.predict(images, verbose=0)
        after = renderer.render(K, [(sphere, T)])
    assert np.isfinite(prediction).all()
    assert before.masks[0].sum() > 50
    np.testing.assert_array_equal(before.rgb, after.rgb)
    np.testing.assert_array_equal(before.depth, after.depth)
