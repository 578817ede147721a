"""The adverse events of a cruise, park or AVP test: their settings, the drawn scenario, placement and judging."""
