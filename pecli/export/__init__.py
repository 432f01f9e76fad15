"""Export a checkpoint for a robot: one ONNX graph (normalisation, belief, actor, action scaling) and a sidecar.

``export_checkpoint`` writes and checks an export, ``check_export`` checks one again, and ``export_network``
exports a network trained by another library. The graph takes SI state estimates and returns SI
commands; :mod:`pecli.runtime` runs it on a robot with NumPy and ONNX Runtime only, and
:class:`pecli.policies.exported.ExportedPolicy` plays it in the game.
"""

from pecli.export.check import TOLERANCE, ParityReport, check_parity
from pecli.export.exporter import ExportResult, check_export, export_checkpoint
from pecli.export.network import NetworkPolicy, export_network

__all__ = [
    "TOLERANCE",
    "ExportResult",
    "NetworkPolicy",
    "ParityReport",
    "check_export",
    "check_parity",
    "export_checkpoint",
    "export_network",
]
