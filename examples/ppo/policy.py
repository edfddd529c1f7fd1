"""The PPO baseline's submission: the trained network, exported to ONNX, run by onnxruntime.

``train.py`` trained it on the arena's own simulator (``learn.gym_env``). With
``observation_format: arrays`` (``agent.yaml``) the sandbox hands the policy the very arrays the
training environment gave, so ``features.py`` computes its inputs exactly as in training.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnxruntime
from features import features, to_action

MODEL = Path(__file__).with_name("policy.onnx")


class Policy:
    def __init__(self, model: Path = MODEL) -> None:
        options = onnxruntime.SessionOptions()
        options.intra_op_num_threads = 1  # the sandbox gives one CPU's worth of time
        options.inter_op_num_threads = 1
        self.session = onnxruntime.InferenceSession(
            str(model), options, providers=["CPUExecutionProvider"]
        )

    def act(self, obs: dict[str, dict]) -> dict[str, list[float]]:
        return {agent_id: self.drive(o) for agent_id, o in obs.items()}

    def drive(self, obs: dict) -> list[float]:
        x = features(obs)
        (logits,) = self.session.run(None, {"image": x["image"][None], "vector": x["vector"][None]})
        return to_action(int(np.argmax(logits[0])), float(obs["ego_vehicle_state"]["speed"][0]))
