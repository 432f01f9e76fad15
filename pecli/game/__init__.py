"""The pursuit-evasion game: batched NumPy simulation, sensors, observations, PettingZoo adapter.

No torch here: the game is plain NumPy.
"""

from pecli.game.game import Game, StepResult
from pecli.game.observation import Decoded, ObservationCodec
from pecli.game.single import SingleGame, SingleStep

__all__ = ["Decoded", "Game", "ObservationCodec", "SingleGame", "SingleStep", "StepResult"]
