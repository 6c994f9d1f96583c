"""The tiny training set-up the training tests share: one short row, no people, a 16-unit network."""

TINY_ENV = {"n_rows": 1, "row_length": 3.0, "n_people": 0, "max_episode_steps": 40}
TINY_HP = {
    "n_envs": 2,
    "env_kwargs": TINY_ENV,
    # the tiny fixed scene: no training distribution (the YAML draws scenes), which would override it
    "train_env_kwargs": {"scene_distribution": "off"},
    "eval_env_kwargs": {"scene_distribution": "off"},
    "algo_kwargs": {"n_steps": 32, "batch_size": 32, "n_epochs": 1},
    "policy_kwargs": {"net_arch": {"pi": [16], "vf": [16]}},
    "eval_freq": 64,
    "eval_episodes": 1,
    "checkpoint_freq": 64,
}

