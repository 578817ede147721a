"""Plumbing every stage uses; it imports none of the stages.

- ``errors``: :class:`GarageMJError`, the one base class of errors a user can cause.
- ``fsutil``: atomic writes, output-folder locks.
- ``config``: typed, frozen config dataclasses loaded from TOML (unknown keys are an error).
- ``backends``: the local process pool and Ray, behind one ``map_unordered``.
- ``geometry``: grid directions and small geometric helpers.
- ``lazy``: ``lazy_exports``, the lazy re-exports of a stage's public names (``scene``, ``export``).
- ``model_file``: the one door through which every model, checkpoint, replay buffer and generator file is
  read, as weights and plain fields (nothing in a file is run).
- ``words``: ``a_noun``, the article of a word a message fills in ("an obstacle", "a parked car").
"""

__version__ = "0.2.0"
