"""The behaviour-cloning policy trained by ``train.py``: the observation vector of
``features.py`` through the MLP gives the expert's speed, which the lane controller
(``LaneWithContinuousSpeed``) drives at, in the current lane."""

import os
from pathlib import Path

import numpy as np
from features import observation_vector


class Policy:
    def __init__(self):
        weights = np.load(Path(os.environ["ARENA_MODEL_DIR"]) / "weights.npz")
        self.p = {k: weights[k] for k in weights.files}

    def act(self, obs):
        return {agent_id: self.drive(agent_obs) for agent_id, agent_obs in obs.items()}

    def drive(self, obs):
        p = self.p
        x = (observation_vector(obs) - p["x_mean"]) / p["x_std"]
        h = np.maximum(x @ p["w0"] + p["b0"], 0)
        h = np.maximum(h @ p["w1"] + p["b1"], 0)
        speed = float(((h @ p["w2"] + p["b2"]) * p["y_std"] + p["y_mean"])[0])
        return [max(speed, 0.0), 0.0]
