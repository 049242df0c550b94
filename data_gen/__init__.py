"""Synthetic BOP-format data from meshes: scene sampling, domain randomization, writers, workers.

Entry points: :func:`data_gen.generator.generate` with a :class:`data_gen.config.GenerationConfig`,
or the ``paz6d generate`` command (:mod:`data_gen.cli`). Importing this package loads no GL.
"""
