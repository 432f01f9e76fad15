"""pecli: pursuit-evasion between car-like robots with limited sensors.

The batched game lives in :mod:`pecli.game`, scenarios in :mod:`pecli.scenario`,
everything that acts implements :class:`pecli.policies.Policy`.
"""

__version__ = "0.14.0"
