"""The simulated car and its test: vehicle, camera, outcome monitor and the drive env ``GarageDrive-v0``."""
