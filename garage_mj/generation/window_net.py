"""Q-network input layers for painter windows observed as block codes.

``GarageGenVecEnv(window="codes")`` observes the k x k window as k * k block codes and the replay
buffer stores them so. Two input layers turn them back into what the single env observes (the
one-hot rows ``eye(NUM_CODES)[codes]``, then the state values: the painter's 7, or ``state_values`` of them,
12 for the conditioned painter's, whose 5 band values follow the 7):

- :class:`OneHotWindow` expands the codes to that one-hot vector, and the MLP's first linear layer
  multiplies it as usual. Models trained with it load with it.
- :class:`WindowLayer` *is* that first linear layer (and its ReLU), computed from the codes: a
  one-hot vector times a weight matrix is the sum of the matrix rows its ones pick, so the forward
  pass looks up k * k rows (``embedding_bag``) instead of multiplying a 497-wide, 90%-zero input.
  The gradient is the usual dense product. The network is the same function of the same
  observation with the same initial weights; on one CPU core a gradient step of the fast learner's
  (64, 64) network at batch 256 takes about three quarters of the time (``eval/bench_window_layer.py``).
"""

from __future__ import annotations

import gymnasium as gym
import torch
import torch.nn.functional as F
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

from garage_mj.grid.blocks import NUM_CODES

STATE_VALUES = 7  # error index, coverage, connected flag, one-hot heading (the default: saved models built so)


def _cells(observation_space: gym.spaces.Box, state_values: int) -> int:
    """The window cells of a codes observation with ``state_values`` values after them."""
    cells = observation_space.shape[0] - state_values
    if state_values < 0 or cells < 1:
        raise ValueError(f"a codes observation of {observation_space.shape[0]} values cannot hold a window "
                         f"and {state_values} state values")
    return cells


class OneHotWindow(BaseFeaturesExtractor):
    """(batch, k * k + S) codes and S state values -> (batch, k * k * NUM_CODES + S) one-hot window and state
    (S = ``state_values``)."""

    def __init__(self, observation_space: gym.spaces.Box, state_values: int = STATE_VALUES) -> None:
        cells = _cells(observation_space, state_values)
        super().__init__(observation_space, features_dim=cells * NUM_CODES + state_values)
        self.cells = cells
        # the one-hot rows, looked up by code (5x faster on CPU than one_hot() and a cast)
        self.register_buffer("eye", torch.eye(NUM_CODES), persistent=False)

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        codes = observations[:, : self.cells].long()
        one_hot = torch.nn.functional.embedding(codes, self.eye.to(observations.dtype)).flatten(1)
        return torch.cat([one_hot, observations[:, self.cells :]], dim=1)


class _OneHotProduct(torch.autograd.Function):
    """``one_hot(index) @ table`` for an index matrix whose rows name distinct rows of ``table``.

    Forward: the sum of the named rows (``embedding_bag``). Backward: the dense product
    ``one_hot.T @ grad``, which on CPU is several times faster than the backward passes of
    ``embedding_bag`` or ``index_add_`` for these sizes.
    """

    @staticmethod
    def forward(ctx, index: torch.Tensor, table: torch.Tensor) -> torch.Tensor:
        ctx.save_for_backward(index)
        ctx.rows = table.shape[0]
        return F.embedding_bag(index, table, mode="sum")

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        (index,) = ctx.saved_tensors
        return None, one_hot_product_backward(index, ctx.rows, grad)


def one_hot_product_backward(index: torch.Tensor, rows: int, grad: torch.Tensor) -> torch.Tensor:
    """The gradient of ``one_hot(index) @ table`` (``rows`` rows) for the output gradient ``grad``."""
    one_hot = grad.new_zeros(index.shape[0], rows).scatter_(1, index, 1.0)
    return one_hot.t() @ grad


class WindowLayer(BaseFeaturesExtractor):
    """(batch, k * k + S) codes and S state values -> ReLU of the Q-network's first layer, ``width`` values
    (S = ``state_values``).

    The same function as ``Linear(k * k * NUM_CODES + S, width)`` and a ReLU applied to
    :class:`OneHotWindow`'s output, with the same initial weights (the layer is created as that
    ``Linear`` and its weight split into the window's rows and the state's columns).
    """

    def __init__(self, observation_space: gym.spaces.Box, width: int = 64, state_values: int = STATE_VALUES) -> None:
        cells = _cells(observation_space, state_values)
        super().__init__(observation_space, features_dim=width)
        self.cells = cells
        dense = nn.Linear(cells * NUM_CODES + state_values, width)  # its initialisation, then split
        n = cells * NUM_CODES
        # row p * NUM_CODES + code: the weights of "cell p holds code"
        self.window = nn.Parameter(dense.weight.detach()[:, :n].t().contiguous())
        self.state = nn.utils.skip_init(nn.Linear, state_values, width)  # no draw: the next layers' stay as they were
        with torch.no_grad():
            self.state.weight.copy_(dense.weight[:, n:])
            self.state.bias.copy_(dense.bias)
        self.register_buffer("offsets", torch.arange(cells) * NUM_CODES, persistent=False)

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        index, state = self.inputs(observations)
        window = _OneHotProduct.apply(index, self.window)
        return torch.relu(window + self.state(state))

    def inputs(self, observations: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The rows of :attr:`window` the observed codes pick (batch, cells) and the state values."""
        return observations[:, : self.cells].long() + self.offsets, observations[:, self.cells :]
