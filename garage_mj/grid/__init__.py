"""The garage as a grid: the encoding matrix and everything computed from it alone.

- ``blocks``: block codes (FREE 0, ROAD 1, OBSTACLE 2, ... ENTRANCE 7, EXIT 8) and the six-stall axis.
- ``garage``: the :class:`Garage` model and its validation.
- ``rules``: the stall rule that recolours a painted cell's neighbours.
- ``road_segments``: road segments and key nodes of the grid (the paper's E[X] and E[Y]).
- ``metrics``: coverage and difficulty (:func:`evaluate`).
- ``reward``: the painter's reward terms and the utility weights that metrics score with.
- ``map_io``: map files (shipped and user's).
- ``painters``: scripted painters, no learning (tests, seeds of the search); the painter MDP is
  :mod:`garage_mj.generation.gen_env`.
- ``image``, ``text``: pictures and text drawings of a grid.
"""
