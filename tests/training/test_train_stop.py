"""Stopping `agri train` early (Ctrl-C, SIGTERM) still writes a complete, loadable run directory."""

import json
import os
import signal

import gymnasium as gym

import agri_training.train as train_module
from agri_training.evaluation.policies import load_policy
from agri_training.learned.policy import LearnedPolicy
from agri_training.train import TrainRequest, train

ENV_ID = "agri_envs/GreenhouseNav-v2"
TINY_ENV = {"n_rows": 1, "row_length": 3.0, "n_people": 0, "max_episode_steps": 40}
TINY_HP = {
    "n_envs": 1,
    "env_kwargs": TINY_ENV,
    # the tiny fixed scene: no training distribution (the YAML draws scenes), which would override it
    "train_env_kwargs": {"scene_distribution": "off"},
    "eval_env_kwargs": {"scene_distribution": "off"},
    "algo_kwargs": {"n_steps": 32, "batch_size": 32, "n_epochs": 1},
    "policy_kwargs": {"net_arch": {"pi": [8], "vf": [8]}},
    "eval_freq": 10_000,
    "eval_episodes": 1,
    "checkpoint_freq": 0,
}


def test_sigterm_stops_training_and_keeps_the_run(tmp_path, monkeypatch):
    make = train_module._make_callback

    def terminating_callback(config, run_dir, progress, on_eval=None):
        callback = make(config, run_dir, progress, on_eval)
        on_step = callback._on_step

        def step():
            if callback.num_timesteps >= 64:
                os.kill(os.getpid(), signal.SIGTERM)
            return on_step()

        callback._on_step = step
        return callback

    monkeypatch.setattr(train_module, "_make_callback", terminating_callback)
    before = signal.getsignal(signal.SIGTERM)
    out = train(TrainRequest(ENV_ID, "ppo", tmp_path / "run", timesteps=100_000, overrides=TINY_HP, progress=False))
    assert signal.getsignal(signal.SIGTERM) == before  # the handler is restored
    meta = json.loads((out / "meta.json").read_text())
    assert meta["stopped_early"] and 64 <= meta["timesteps_done"] < 100_000
    env = gym.make(ENV_ID, localization="ground_truth", **TINY_ENV)
    assert isinstance(load_policy(str(out), env), LearnedPolicy)
