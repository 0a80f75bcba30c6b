"""The ``peghole`` command: the top-level parser and dispatcher (:mod:`.main`), ``peghole demo``
(:mod:`.demo`) and ``peghole export`` (:mod:`.export`). Each subpackage's own command group is
its ``cli`` module (``peghole_mjx.envs.cli``, ...)."""
