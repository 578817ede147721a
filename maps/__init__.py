"""Shipped initial maps (package data ``garage_mj.maps``); load them with ``garage_mj.load_map``."""
