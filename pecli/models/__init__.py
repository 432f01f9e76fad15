"""The learned models: Stable-Baselines3 algorithms with a centralised critic, their networks and checkpoint files.

Below both :mod:`pecli.policies` (which plays a checkpoint) and :mod:`pecli.rl` (which trains one).
"""
