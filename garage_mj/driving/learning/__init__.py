"""Training a learned driver: its observation, its network, the fleet env and ``train-driver``."""
