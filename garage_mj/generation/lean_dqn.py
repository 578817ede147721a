"""LeanDQN: stable-baselines3's DQN with less work around each gradient step and action choice.

The fast learner's Q-network is small, so at 32 garages per vector step SB3's own bookkeeping is a
large part of a gradient step: switching every module between train and eval mode twice per step,
clipping the gradient norm through a generic path over both networks' parameters, and turning a
batch of observations into actions through the general ``predict`` path. :class:`LeanDQN` keeps the
algorithm and every number of SB3's :class:`~stable_baselines3.DQN` (the same replay samples, random
draws, loss, clipping and optimiser step, so the same seed trains the same network bit for bit,
``tests/test_vec_env.py``) and drops that overhead:

- no mode switches when the policy holds no layer that behaves differently in training (dropout,
  batch norm), neither in the gradient step nor before each step of the envs; with such a layer it
  does what DQN does;
- the gradient norm is clipped by the two steps ``torch.nn.utils.clip_grad_norm_`` is made of
  (``get_total_norm``, ``clip_grads_with_norm_``), with ``foreach`` over the online network's gradients
  gathered once, not through its generic path over both networks' parameters;
- a batch of observations is answered straight from the Q-network's argmax (epsilon-greedy as DQN's
  ``predict``: with probability epsilon the whole batch acts at random);
- for the fast learner's Q-network (a :class:`~garage_mj.generation.window_net.WindowLayer`, then
  linear layers with ReLUs between them) the gradient is taken by hand (:class:`HandGradient`): the
  forward pass keeps its activations and the backward pass calls the very kernels autograd would
  (``mm`` in the same orientation, ``threshold_backward``, ``smooth_l1_loss_backward``), so the
  gradients are the same to the bit, without autograd's graph and engine, which at these sizes cost
  more than the arithmetic. The target network's Q-values and the action choice run the same
  functional forward pass, without the modules' call overhead. Any other network goes through
  autograd.

``eval/bench_lean_dqn.py`` measures what it saves. Models it saves load with ``DQN.load`` and the other
way round.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch as th
import torch.nn.functional as F
from stable_baselines3 import DQN
from torch import nn
from torch.nn.utils import clip_grads_with_norm_, get_total_norm

from garage_mj.generation.window_net import WindowLayer, one_hot_product_backward

_MODAL = (nn.modules.dropout._DropoutNd, nn.modules.batchnorm._BatchNorm)  # layers that read .training


class LeanDQN(DQN):
    """:class:`~stable_baselines3.DQN` with the same results and less per-step overhead (module docstring)."""

    def _setup_model(self) -> None:
        super()._setup_model()
        self._modeless = not any(isinstance(m, _MODAL) for m in self.policy.modules())
        self._grad_params = [p for p in self.q_net.parameters() if p.requires_grad]
        self._hand = HandGradient.of(self.q_net, self.q_net_target) if self._modeless else None
        if self._modeless:  # nothing reads .training: collect_rollouts' switch before every step has nothing to do
            self.policy.set_training_mode = _keep_mode  # type: ignore[method-assign]

    def _excluded_save_params(self) -> list[str]:
        # built from the policy by _setup_model, which a load runs again: not saved (the hand gradient's
        # modules and the parameter list would double the size of every checkpoint)
        return [*super()._excluded_save_params(), "_modeless", "_grad_params", "_hand"]

    def train(self, gradient_steps: int, batch_size: int = 100) -> None:
        if not self._modeless:
            return super().train(gradient_steps, batch_size)
        self._update_learning_rate(self.policy.optimizer)
        losses = []
        hand = self._hand
        for _ in range(gradient_steps):
            data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[union-attr]
            discounts = data.discounts if data.discounts is not None else self.gamma
            with th.no_grad():
                next_q = (hand.target_q(data.next_observations) if hand else self.q_net_target(data.next_observations))
                target_q = data.rewards + (1 - data.dones) * discounts * next_q.max(dim=1)[0].reshape(-1, 1)
            if hand:
                losses.append(hand.set_gradients(data.observations, data.actions.long(), target_q))
            else:
                current_q = th.gather(self.q_net(data.observations), dim=1, index=data.actions.long())
                loss = F.smooth_l1_loss(current_q, target_q)
                losses.append(loss.item())
                self.policy.optimizer.zero_grad()
                loss.backward()
            self._clip_gradients()
            self.policy.optimizer.step()
        self._n_updates += gradient_steps
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/loss", np.mean(losses))

    def _clip_gradients(self) -> None:
        """``clip_grad_norm_(parameters, max_grad_norm)``, from its own two steps."""
        params = self._grad_params
        total = get_total_norm([p.grad for p in params if p.grad is not None], foreach=True)
        clip_grads_with_norm_(params, self.max_grad_norm, total, foreach=True)

    def predict(self, observation: Any, state: tuple[np.ndarray, ...] | None = None,
                episode_start: np.ndarray | None = None, deterministic: bool = False):
        batched = (isinstance(observation, np.ndarray) and self._modeless
                   and observation.shape[1:] == self.observation_space.shape and observation.ndim >= 2)
        if not batched:
            return super().predict(observation, state, episode_start, deterministic)
        if not deterministic and np.random.rand() < self.exploration_rate:
            return np.array([self.action_space.sample() for _ in range(observation.shape[0])]), state
        with th.no_grad():
            obs = th.as_tensor(observation, device=self.device).float()
            q = self._hand.q_values(obs) if self._hand else self.q_net(obs)
        return q.argmax(dim=1).cpu().numpy(), state


class HandGradient:
    """The gradient of DQN's Huber loss for a Q-network of a :class:`WindowLayer` and linear layers, by hand.

    The network: ``h = relu(sum of the window rows the codes pick + state @ W_s.T + b_s)``, then
    ``h = relu(h @ W.T + b)`` for every linear layer but the last, and ``q = h @ W.T + b``. The forward
    pass runs the layers' own functional ops; the backward pass calls the kernels autograd's
    formulas call for them, in the same orientation (``addmm``'s weight gradient as
    ``grad.t().mm(input)``, ``threshold_backward`` for each ReLU, ``scatter_add_`` for the gather,
    ``smooth_l1_loss_backward`` for the loss, :class:`~garage_mj.generation.window_net.WindowLayer`'s
    own dense product for the window rows), so each gradient equals autograd's bit for bit
    (``tests/test_vec_env.py`` trains both from one seed).
    """

    def __init__(self, online: tuple[WindowLayer, list[nn.Linear]], target: tuple[WindowLayer, list[nn.Linear]]) -> None:
        self.window, self.linears = online
        self.target_window, self.target_linears = target
        self._ones = th.ones((), device=self.window.window.device)  # d loss / d loss

    @classmethod
    def of(cls, q_net: nn.Module, q_net_target: nn.Module) -> HandGradient | None:
        """The hand gradient of SB3 ``QNetwork`` s of this shape (and their target copy), else None."""
        online, target = _layers(q_net), _layers(q_net_target)
        return cls(online, target) if online and target else None

    def q_values(self, observations: th.Tensor) -> th.Tensor:
        """The online network's Q-values (what ``q_net(observations)`` returns), without autograd's graph."""
        return _q_values(self.window, self.linears, observations)

    def target_q(self, observations: th.Tensor) -> th.Tensor:
        """The target network's Q-values (what ``q_net_target(observations)`` returns), without autograd's graph."""
        return _q_values(self.target_window, self.target_linears, observations)

    def set_gradients(self, observations: th.Tensor, actions: th.Tensor, target_q: th.Tensor) -> float:
        """Sets ``.grad`` of every online parameter to the gradient of the mean Huber loss between the
        Q-values of ``actions`` and ``target_q``; returns the loss."""
        with th.no_grad():
            window, linears = self.window, self.linears
            index, state, inputs, q = _forward(window, linears, observations)
            current_q = th.gather(q, 1, actions)
            loss = F.smooth_l1_loss(current_q, target_q)
            g = th.ops.aten.smooth_l1_loss_backward(self._ones, current_q, target_q, 1, 1.0)  # 1: mean
            g = q.new_zeros(q.shape).scatter_add_(1, actions, g)
            for lin, x in zip(reversed(linears), reversed(inputs)):
                lin.weight.grad = g.t().mm(x)
                lin.bias.grad = g.sum(0)
                g = th.ops.aten.threshold_backward(g.mm(lin.weight), x, 0)
            window.state.weight.grad = g.t().mm(state)
            window.state.bias.grad = g.sum(0)
            window.window.grad = one_hot_product_backward(index, window.window.shape[0], g)
        return loss.item()


def _layers(q_net: nn.Module) -> tuple[WindowLayer, list[nn.Linear]] | None:
    """A ``QNetwork`` 's WindowLayer and linear layers when it is a WindowLayer, then Linear (ReLU, Linear)*."""
    extractor, mlp = getattr(q_net, "features_extractor", None), getattr(q_net, "q_net", None)
    if type(extractor) is not WindowLayer or not isinstance(mlp, nn.Sequential) or len(mlp) % 2 == 0:
        return None
    linears, relus = list(mlp)[0::2], list(mlp)[1::2]
    if not all(type(m) is nn.Linear for m in linears) or not all(type(m) is nn.ReLU for m in relus):
        return None
    return extractor, linears


def _keep_mode(mode: bool) -> None:
    """``set_training_mode`` of a policy without a layer that reads ``.training``."""


def _q_values(window: WindowLayer, linears: list[nn.Linear], observations: th.Tensor) -> th.Tensor:
    return _forward(window, linears, observations)[3]


def _forward(window: WindowLayer, linears: list[nn.Linear], observations: th.Tensor
             ) -> tuple[th.Tensor, th.Tensor, list[th.Tensor], th.Tensor]:
    """The Q-network's forward pass outside autograd: the window rows the codes pick, the state values, the
    input of each linear layer (the first one :meth:`WindowLayer.forward`'s output) and the Q-values."""
    index, state = window.inputs(observations)
    inputs = [th.relu(F.embedding_bag(index, window.window, mode="sum") + window.state(state))]
    for lin in linears[:-1]:
        inputs.append(th.relu(F.linear(inputs[-1], lin.weight, lin.bias)))
    return index, state, inputs, F.linear(inputs[-1], linears[-1].weight, linears[-1].bias)
