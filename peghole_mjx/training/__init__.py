"""SAC training on the MJX envs (Brax), evaluation against the scripted baseline, plots.

Modules: :mod:`config` (hyperparameters from ``train/configs``), :mod:`sac` (the learner),
:mod:`run` (a run on disk: metrics, checkpoints, resume), :mod:`evaluate`, :mod:`plots`,
:mod:`video`, :mod:`cli`.
"""
