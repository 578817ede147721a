"""The adverse events of a cruise test: their settings, the drawn scenario, placement and judging."""
