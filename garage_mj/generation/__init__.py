"""Generation: the painter MDP, DQN training, conditioned generation, the search and the library.

- ``gen_env``: ``GarageGen-v0``, the turtle-style painter of docs/spec.md section 3, and its reward config.
- ``cond_env``: ``GarageGenCond-v0``, the painter conditioned on a difficulty target.
- ``vec_env``: ``GarageGenVecEnv``, N painters stepped as one SB3 ``VecEnv`` (the fast learner's env).
- ``window_net``: ``WindowLayer``, the Q-network's first layer computed from a window of block codes, and
  ``OneHotWindow``, which expands them to the one-hot input (models trained with it).
- ``lean_dqn``: ``LeanDQN``, SB3's DQN with the same results and less overhead per step (the fast learner's algorithm).
- ``runs``: the lifecycle of a resumable DQN run (run folder, checkpoints, resume, Ctrl-C) both trainings share.
- ``training``: DQN on the painter (the ``paper`` and ``fast`` learners); every usable garage goes to the library as it is found.
- ``conditioned``: the difficulty-conditioned generator: train it, find the shipped one, load it.
- ``generator``: ``garage-mj generate``, garages on demand in a difficulty band.
- ``search``: the band-directed hill-climb that fills bins the policy does not reach.
- ``library``: the scenario library (embedded SQLite): store, query, stratified sample, stats; stored route difficulties.
- ``library_format``: the library file's schema, its integrity checks (header, body, rows) and the row type.
- ``protocol``: the paper's protocol (maps x seeds x timesteps) trained into one library, resumable.
- ``remote``: runs trained on other Ray nodes, streamed back: this process alone writes the library and run folders.
- ``progress``: where each run of a protocol stands (new, running, resume, finished), for ``generation/run.py --status``.
"""
