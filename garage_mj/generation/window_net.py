"""OneHotWindow: the Q-network's input layer for painter windows observed as block codes.

``GarageGenVecEnv(window="codes")`` observes the k x k window as k * k block codes and the replay
buffer stores them so; this features extractor turns them back into the one-hot rows the
single env observes (``eye(NUM_CODES)[codes]``, then the 7 state values), so the MLP on top sees
exactly the paper's input and the network is the same function of the same observation.
"""

from __future__ import annotations

import gymnasium as gym
import torch
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

from garage_mj.grid.blocks import NUM_CODES

STATE_VALUES = 7  # error index, coverage, connected flag, one-hot heading


class OneHotWindow(BaseFeaturesExtractor):
    """(batch, k * k + 7) codes and state values -> (batch, k * k * NUM_CODES + 7) one-hot window and state."""

    def __init__(self, observation_space: gym.spaces.Box) -> None:
        cells = observation_space.shape[0] - STATE_VALUES
        super().__init__(observation_space, features_dim=cells * NUM_CODES + STATE_VALUES)
        self.cells = cells
        # the one-hot rows, looked up by code (5x faster on CPU than one_hot() and a cast)
        self.register_buffer("eye", torch.eye(NUM_CODES), persistent=False)

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        codes = observations[:, : self.cells].long()
        one_hot = torch.nn.functional.embedding(codes, self.eye.to(observations.dtype)).flatten(1)
        return torch.cat([one_hot, observations[:, self.cells :]], dim=1)
