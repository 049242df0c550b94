"""Augmented Autoencoder (implicit 6D pose): model, training views and augmentation, trainer,
run directory and the ``ImplicitPose6D`` pipeline. Importing this package loads nothing heavy."""
