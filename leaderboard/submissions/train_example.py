"""The example submission (SB3 PPO, 30k steps on GreenhouseNav-v2), saved as an SB3 zip and its actor exported to ONNX.

The steps of docs/bring-your-own-policy.md, run from this folder: `python train_example.py` (about 4 minutes on
one of 2 busy cores). Its entries on greenhouse-sim-loop show the two file formats on the leaderboard; the
policy itself is barely trained.
"""

import gymnasium as gym
import torch
from stable_baselines3 import PPO

import agri_envs  # noqa: F401

torch.set_num_threads(1)
env = gym.make("agri_envs/GreenhouseNav-v2", localization="ground_truth")
model = PPO(
    "MultiInputPolicy", env, n_steps=512, batch_size=64, seed=0, device="cpu", policy_kwargs={"net_arch": [64, 64]}
)
model.learn(total_timesteps=30_000)
model.save("example-ppo-nav.zip")


class Actor(torch.nn.Module):
    """The deterministic action of an SB3 PPO policy: the mean, from the flattened observation."""

    def __init__(self, policy):
        super().__init__()
        self.policy = policy

    def forward(self, flat_observation):
        """The action mean."""
        return self.policy.action_net(self.policy.mlp_extractor.forward_actor(flat_observation))


width = gym.spaces.flatdim(env.observation_space)
torch.onnx.export(
    Actor(model.policy).eval(),
    (torch.zeros(1, width),),
    "example-ppo-nav.onnx",
    external_data=False,
    input_names=["observation"],
    output_names=["action"],
)
for name in ("example-ppo-nav.onnx", "example-ppo-nav.zip"):
    with open(name + ".yaml", "w") as sidecar:
        sidecar.write(
            "env_id: agri_envs/GreenhouseNav-v2\nenv_kwargs: {localization: ground_truth}\n"
            "privileged: true  # it reads the waypoints from the true pose\n"
        )
