"""A submission written as the Driving SMARTS 2022 organisers' example agent was (SMARTS
``comp-1``, ``competition/track1/submission``), run unmodified by the tests: the same imports, the
same wrappers in the same order (``FormatObs`` with comp-1's keys, ``FormatAction``, a wrapper
saving the ego's pose, a discrete action wrapper, a wrapper filtering the observation down to a
recoloured top-down image and the goal's distance and heading, ``FrameStack`` and a concatenating
wrapper), and a stable-baselines3 PPO model loaded from ``saved_model.zip`` beside it with a
feature extractor of its own (``network.py``). Written for Driving Arena's tests, not copied.

The test makes ``saved_model.zip`` (a small untrained PPO) before it evaluates this folder.
"""

import sys
from pathlib import Path
from typing import Any, Dict

# To import the submission folder, as the kit's template does.
sys.path.insert(0, str(Path(__file__).resolve().parents[0]))


class BasePolicy:
    def act(self, obs: Dict[str, Any]):
        raise NotImplementedError


def submitted_wrappers():
    from action import Action as DiscreteAction
    from observation import Concatenate, FilterObs, SaveObs

    from smarts.core.controllers import ActionSpaceType
    from smarts.env.wrappers.format_action import FormatAction
    from smarts.env.wrappers.format_obs import FormatObs
    from smarts.env.wrappers.frame_stack import FrameStack

    return [
        FormatObs,
        lambda env: FormatAction(env=env, space=ActionSpaceType["TargetPose"]),
        SaveObs,
        DiscreteAction,
        FilterObs,
        lambda env: FrameStack(env=env, num_stack=3),
        lambda env: Concatenate(env=env, channels_order="first"),
    ]


class Policy(BasePolicy):
    def __init__(self):
        import stable_baselines3 as sb3lib

        import network  # noqa: F401  (the model's feature extractor lives there)

        model_path = Path(__file__).resolve().parents[0] / "saved_model.zip"
        self.model = sb3lib.PPO.load(model_path)

    def act(self, obs: Dict[str, Any]):
        wrapped_act = {}
        for agent_id, agent_obs in obs.items():
            action, _ = self.model.predict(observation=agent_obs, deterministic=True)
            wrapped_act.update({agent_id: action})
        return wrapped_act
