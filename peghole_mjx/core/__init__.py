"""The package's base modules, imported from every layer: one-line errors, input checks, progress
bars, memory checks, optional and MJX imports, NumPy rotations, pytree names, the commands' lazy
imports and process-wide settings. None imports JAX at import time except :mod:`._mjx`."""
