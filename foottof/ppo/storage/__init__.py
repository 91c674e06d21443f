"""The trainer's storage: checkpoints, their integrity records, input growth on restore, run folders.

Nothing is imported here: ``run_dir`` and ``integrity`` load without JAX.
"""
