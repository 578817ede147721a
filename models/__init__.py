"""Reusable MJCF models (package data ``garage_mj.models``), Menagerie style: XML plus a README."""
