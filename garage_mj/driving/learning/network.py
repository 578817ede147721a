"""The learned driver's network body: a small CNN over the camera, joined with the route vector.

:class:`CameraRouteExtractor` is a stable-baselines3 features extractor for
:func:`~garage_mj.driving.learning.observation.learned_space`: NatureCNN's three convolutions (8x8 stride 4,
4x4 stride 2, 3x3 stride 1, each with a ReLU; Mnih et al., 2015) with ``channels`` filters, a linear
layer with a ReLU to ``cnn_features``, and the ``vector`` appended as it is. The policy's MLP
(``net_arch``) maps that to the Q-values.

Why not SB3's ``CombinedExtractor`` (the same layers at the default 32/64/64 filters): the filter
counts are a setting here (fewer make a cheaper act), and the forward pass of a batch of one is
leaner: it calls the layers' functions on their own parameters (this module's layers, not a copy of
SB3's), skipping the per-module call overhead, and it scales the uint8 image to [0, 1] itself, so
SB3's per-call image-space checks are skipped too (``normalize_images=False``). The result is that
of calling the layers.

Imported by :mod:`~garage_mj.driving.learning.train` and by stable-baselines3 when it loads a model
zip that names this class (torch is imported here at the top: only learned-driver code imports it).
"""

from __future__ import annotations

import torch
from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn
from torch.nn import functional as F

KERNELS = ((8, 4), (4, 2), (3, 1))  # (kernel, stride) of the three convolutions, NatureCNN's


class CameraRouteExtractor(BaseFeaturesExtractor):
    """``image`` through a CNN to ``cnn_features``, then ``vector``: ``cnn_features + len(vector)`` features.

    Args:
        observation_space: a :func:`~garage_mj.driving.learning.observation.learned_space` dict (``image``
            (C, H, W) uint8, scaled here to [0, 1]: train it with ``normalize_images=False`` in the
            policy's kwargs, as :mod:`~garage_mj.driving.learning.train` does, so SB3 does not scale it too;
            ``vector`` (N,)).
        channels: filters of the three convolutions.
        cnn_features: width of the image features.
    """

    def __init__(self, observation_space: spaces.Dict, channels: tuple[int, ...] = (32, 64, 64),
                 cnn_features: int = 32) -> None:
        image, vector = observation_space["image"], observation_space["vector"]
        if len(channels) != len(KERNELS) or min(channels) < 1:
            raise ValueError(f"channels must be {len(KERNELS)} positive filter counts, got {tuple(channels)}")
        super().__init__(observation_space, features_dim=cnn_features + int(vector.shape[0]))
        convs, depth = [], image.shape[0]
        for width, (kernel, stride) in zip(channels, KERNELS):
            convs.append(nn.Conv2d(depth, width, kernel, stride))
            depth = width
        self.convs = nn.ModuleList(convs)
        with torch.no_grad():  # the flattened size for this camera
            n_flat = self._conv(torch.zeros(1, *image.shape)).shape[1]
        self.linear = nn.Linear(n_flat, cnn_features)

    def _conv(self, x: torch.Tensor) -> torch.Tensor:
        for conv in self.convs:
            x = F.relu(F.conv2d(x, conv.weight, conv.bias, conv.stride))
        return x.flatten(1)

    def forward(self, observations: dict[str, torch.Tensor]) -> torch.Tensor:
        image = F.relu(F.linear(self._conv(observations["image"] / 255.0), self.linear.weight, self.linear.bias))
        return torch.cat((image, observations["vector"].flatten(1)), dim=1)


def saved_policy_kwargs(data: dict) -> dict | None:
    """The policy kwargs of a model zip saved with this extractor, rebuilt from the plain fields of its ``data``.

    SB3 pickles ``policy_kwargs`` with the extractor's module path; passing these as
    ``custom_objects={"policy_kwargs": ...}`` to ``load`` rebuilds the same network without unpickling
    that entry, so a model keeps loading wherever this class lives. ``None`` for another extractor.
    """
    kwargs = data.get("policy_kwargs")
    if not isinstance(kwargs, dict) or CameraRouteExtractor.__name__ not in str(kwargs.get("features_extractor_class")):
        return None
    extractor = kwargs.get("features_extractor_kwargs") or {}
    return {"net_arch": list(kwargs.get("net_arch", [])), "features_extractor_class": CameraRouteExtractor,
            "normalize_images": bool(kwargs.get("normalize_images", False)),
            "features_extractor_kwargs": {"channels": tuple(extractor.get("channels", (32, 64, 64))),
                                          "cnn_features": int(extractor.get("cnn_features", 32))}}
