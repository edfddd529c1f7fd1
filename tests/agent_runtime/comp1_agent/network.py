"""The model's feature extractor, in the kit's manner: a CNN over the image, the rest flattened."""

import gym
import torch as th
import torch.nn as nn
from stable_baselines3.common.preprocessing import get_flattened_obs_dim
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor, NatureCNN


class CombinedExtractor(BaseFeaturesExtractor):
    def __init__(self, observation_space: gym.spaces.Dict, cnn_output_dim: int):
        super().__init__(observation_space, features_dim=1)
        extractors = {}
        size = 0
        for key, subspace in observation_space.spaces.items():
            if key == "rgb":
                extractors[key] = NatureCNN(subspace, features_dim=cnn_output_dim)
                size += cnn_output_dim
            else:
                extractors[key] = nn.Flatten()
                size += get_flattened_obs_dim(subspace)
        self.extractors = nn.ModuleDict(extractors)
        self._features_dim = size

    def forward(self, observations) -> th.Tensor:
        return th.cat([f(observations[key]) for key, f in self.extractors.items()], dim=1)
