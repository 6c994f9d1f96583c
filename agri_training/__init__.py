"""Training, evaluation reports and the leaderboard for agri_envs (needs the ``train``/``report`` extras)."""
