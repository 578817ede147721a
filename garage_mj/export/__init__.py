"""Exporters: MJCF scene, meshes, preview and asset packs (and the OpenDRIVE writer)."""
