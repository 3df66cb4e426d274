"""Training, evaluation and experiments on top of Stable-Baselines3."""
