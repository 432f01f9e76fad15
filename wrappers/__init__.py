"""Single-agent training views of the two-player game (Gymnasium / Stable-Baselines3).

The frozen-opponent view arrives with training (``pecli train``); see docs/design.md.
"""
