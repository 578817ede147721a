"""LeanDQN: stable-baselines3's DQN with less work around each gradient step and action choice.

The fast learner's Q-network is small, so at 32 garages per vector step SB3's own bookkeeping is a
large part of a gradient step: switching every module between train and eval mode twice per step,
clipping the gradient norm through a generic path over both networks' parameters, and turning a
batch of observations into actions through the general ``predict`` path. :class:`LeanDQN` keeps the
algorithm and every number of SB3's :class:`~stable_baselines3.DQN` (the same replay samples, random
draws, loss, clipping and optimiser step, so the same seed trains the same network bit for bit,
``tests/test_vec_env.py``) and drops that overhead:

- no mode switches when the policy holds no layer that behaves differently in training (dropout,
  batch norm); with such a layer it does what DQN does;
- the gradient norm is clipped by the two steps ``torch.nn.utils.clip_grad_norm_`` is made of
  (``get_total_norm``, ``clip_grads_with_norm_``), with ``foreach`` over the online network's gradients
  gathered once, not through its generic path over both networks' parameters;
- a batch of observations is answered straight from the Q-network's argmax (epsilon-greedy as DQN's
  ``predict``: with probability epsilon the whole batch acts at random).

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

_MODAL = (nn.modules.dropout._DropoutNd, nn.modules.batchnorm._BatchNorm)  # layers that read .training


class LeanDQN(DQN):
    """:class:`~stable_baselines3.DQN` with the same results and less per-step overhead (module docstring)."""

    def _setup_model(self) -> None:
        super()._setup_model()
        self._modeless = not any(isinstance(m, _MODAL) for m in self.policy.modules())
        self._grad_params = [p for p in self.q_net.parameters() if p.requires_grad]

    def train(self, gradient_steps: int, batch_size: int = 100) -> None:
        if not self._modeless:
            return super().train(gradient_steps, batch_size)
        self._update_learning_rate(self.policy.optimizer)
        losses = []
        for _ in range(gradient_steps):
            data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[union-attr]
            discounts = data.discounts if data.discounts is not None else self.gamma
            with th.no_grad():
                next_q, _ = self.q_net_target(data.next_observations).max(dim=1)
                target_q = data.rewards + (1 - data.dones) * discounts * next_q.reshape(-1, 1)
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
            q = self.q_net(th.as_tensor(observation, device=self.device).float())
        return q.argmax(dim=1).cpu().numpy(), state
