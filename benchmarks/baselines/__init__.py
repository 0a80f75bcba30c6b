"""The thesis's stack rebuilt as a baseline (PyBullet + Stable-Baselines3 SAC) and the time to
success of both stacks on its task. Results: ``benchmarks/results/baselines/``."""
