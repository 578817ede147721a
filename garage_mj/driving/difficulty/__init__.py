"""Relating outcomes to difficulty: regression, the route-difficulty fit and the kept ratings."""
