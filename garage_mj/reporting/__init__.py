"""Reporting: what a person reads of the results.

- ``plots``: convergence curves, coverage x difficulty heatmaps, garage pictures (matplotlib).
- ``analysis``: the regression figure, success against difficulty (numbers in ``driving.regression``).
- ``cruise``: a cruise run as the command runs it: the tests, then its figures (``regression.png``; a park or AVP
  run's ``park_success.png``).
- ``hunt``: a hunt as the command runs it: the search, then the figure, the videos and its HTML report.
- ``experiment``: the generation experiment as ``generation/run.py`` runs it: the protocol's runs, then their figures.
- ``video``: an MP4 of one cruise test with the camera views and the outcome.
- ``report``: the HTML report.
- ``failures``: a cruise run's failures as a report shows them: reasons grouped per class, the first few with an MP4
  and their ``.xosc``.
- ``park``: a park or AVP run as a report shows it: the park table per garage, a top-down picture of each
  failure shown (stalls, obstacles with a legend, the reference plan, the driven path, the final footprint, a
  collision's point, the line an ``outside_stall`` crosses), or of every driven test.
- ``park_figure``: what a park or AVP run is judged by, as a figure: success by level and by maneuver, with counts.
- ``run_report``: a cruise run's own HTML report (``garage-mj cruise --report``), titled with its task.
- ``demo``: the main job end to end on a small garage (train, library, packs, cruise, park, report).
- ``demo_park``: the demo's park and AVP runs with the parking drivers, as its report shows them.
"""
