"""Learning with Stable-Baselines3: the centralised-critic policy, callbacks and the training loop."""
