"""SAC training on the MJX envs (Brax), evaluation against the scripted baseline, plots.

Modules: :mod:`config` (hyperparameters from ``train/configs``), :mod:`sac` (the learner),
:mod:`run` (the training driver: a run on disk, its checkpoints and resume; :mod:`seeds`, several
seeds), :mod:`checkpoints`, :mod:`logs`, :mod:`evaluate`, :mod:`plots`,
:mod:`video`, :mod:`cli` (parsers) and :mod:`commands`.
"""
