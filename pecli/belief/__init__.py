"""Beliefs about where the unseen opponent is: BiMDN (the paper's), a UKF and an image-based baseline.

Every belief is a function of the same input, the history window of the player's own
observations (:class:`pecli.game.memory.HistoryWindow`), and predicts the opponent's position in
the world frame, normalised by the arena's half-extents.
"""

BELIEF_KINDS = ("none", "bimdn", "bimdn-mixed", "ukf", "image")
