"""The exported graph: SI inputs → normalisation → belief → actor → SI command, as one torch module.

It reproduces :meth:`pecli.policies.learned.LearnedPolicy._decide` (the actor's deterministic action of its features)
with the unit conversions around it, and is traced to ONNX by :func:`to_onnx`.

Inputs (``B`` is the batch, dynamic):

``obs``      ``(B, frame_stack, dim)`` float64: the SI rows of the last ``frame_stack`` decisions, oldest first
``history``  ``(B, window, dim)`` float64: every ``history_stride``-th SI row of the last ``history_length``
             ticks, oldest first, zero rows before the game's start (only with a belief)
``uniform``  ``(B, samples)`` float32 in [0, 1) and
``normal``   ``(B, samples, 2)`` float32 standard normal: a mixed belief's random numbers (only ``bimdn-mixed``)

Outputs:

``command``         ``(B, 2)`` float64: the action scaled to physical units (car: steering velocity rad/s and
                    acceleration m/s^2; point mass: a_x, a_y m/s^2), before the simulator's limits on the state
``action``          ``(B, 2)`` float32: the actor's output in [-1, 1], what the simulator takes
``belief_weights``  ``(B, K)``, ``belief_means`` ``(B, K, 2)`` m, ``belief_stds`` ``(B, K, 2)`` m: the belief's
                    mixture over the opponent's position in the world frame (only with a belief)
"""

from __future__ import annotations

import io
import warnings
from typing import Any

import torch as th
from torch import nn

from pecli.belief.mixture import Mixture
from pecli.belief.model import BeliefModel
from pecli.export.beliefs import belief_module
from pecli.export.encoder import SIEncoder
from pecli.game.si import SILayout
from pecli.models.algorithms import deterministic_actor

DEFAULT_OPSET = 17
MIN_OPSET = 13  # the lowest opset every belief kind's operators export to and load back from


def max_opset() -> int:
    """The highest opset the installed torch exporter writes."""
    from torch.onnx import _constants

    return int(getattr(_constants, "ONNX_MAX_OPSET", DEFAULT_OPSET))


def command_limits(layout: SILayout) -> tuple[float, float]:
    """What an action of 1 means in physical units: the input limits the game scales actions by."""
    params = layout.own.params
    if layout.own.has_heading:
        return params.steer_rate_max, params.a_max
    return params.a_max, params.a_max


class PolicyGraph(nn.Module):
    """One player's whole decision, from SI rows to SI command.

    Args:
        actor: the SB3 actor (its ``features_extractor`` holds the belief, if any; its deterministic action is
            :func:`pecli.models.algorithms.deterministic_actor`), on the CPU.
        layout: the SI row layout of the player's role and scenario.
    """

    def __init__(self, actor: nn.Module, layout: SILayout) -> None:
        super().__init__()
        belief: BeliefModel | None = getattr(actor.features_extractor, "belief", None)
        self._build(deterministic_actor(actor), layout, belief)

    @classmethod
    def of_network(cls, network: nn.Module, layout: SILayout) -> PolicyGraph:
        """The graph of a network from the game's observations ``(B, dim)`` to actions ``(B, 2)`` in [-1, 1]
        (one frame, no belief): a player trained by another library."""
        graph = cls.__new__(cls)
        nn.Module.__init__(graph)
        graph._build(network, layout, None)
        return graph

    def _build(self, act: nn.Module, layout: SILayout, belief: BeliefModel | None) -> None:
        self.encoder = SIEncoder(layout)
        self.act = act
        self.belief = belief_module(belief) if belief is not None else None
        self.frame = belief.frame if belief is not None else None  # belief points → the actor's frame
        self.mixed = belief is not None and belief.kind == "bimdn-mixed"
        self.register_buffer("limits", th.tensor(command_limits(layout), dtype=th.float64), persistent=False)
        half = th.tensor((layout.codec.half_x, layout.codec.half_y), dtype=th.float64)
        self.register_buffer("arena_half", half, persistent=False)

    @property
    def input_names(self) -> list[str]:
        return (
            ["obs"] + (["history"] if self.belief is not None else []) + (["uniform", "normal"] if self.mixed else [])
        )

    @property
    def output_names(self) -> list[str]:
        beliefs = ["belief_weights", "belief_means", "belief_stds"] if self.belief is not None else []
        return ["command", "action", *beliefs]

    def forward(
        self,
        obs: th.Tensor,
        history: th.Tensor | None = None,
        uniform: th.Tensor | None = None,
        normal: th.Tensor | None = None,
    ) -> tuple[th.Tensor, ...]:
        beliefs: tuple[th.Tensor, ...] = ()
        if self.belief is None:
            features = self.encoder(obs).flatten(1)  # (B, frame_stack * dim), as the actor's "obs" entry
        else:  # one pass of the encoder over both
            stack = obs.shape[1]
            rows = self.encoder(th.cat([obs, history], dim=1))
            features, window = rows[:, :stack].flatten(1), rows[:, stack:]
            mixture = Mixture(*self.belief(window))
            points = (
                mixture.sample_with(uniform, normal) if self.mixed else mixture.mean()
            )  # as BeliefModel.features_of
            features = th.cat([features, self.frame(points, window[:, -1]).flatten(1)], dim=1)
            beliefs = (
                mixture.weights,
                mixture.means.double() * self.arena_half,
                mixture.stds.double() * self.arena_half,
            )
        action = self.act(features)
        return (action.double() * self.limits, action, *beliefs)


def to_onnx(graph: PolicyGraph, example: dict[str, th.Tensor], opset: int = DEFAULT_OPSET) -> bytes:
    """The graph traced to ONNX (a dynamic batch axis on every input and output), serialised."""
    names = graph.input_names
    buffer = io.BytesIO()
    axes: dict[str, Any] = {name: {0: "batch"} for name in names + graph.output_names}
    graph.eval()
    with warnings.catch_warnings(), th.no_grad():
        # the TorchScript exporter is deprecated in favour of torch.export (which needs onnxscript);
        # it warns about that, and about the LSTM's batch size, which the dynamic axis handles
        warnings.simplefilter("ignore")
        th.onnx.export(
            graph,
            tuple(example[name] for name in names),
            buffer,
            input_names=names,
            output_names=graph.output_names,
            dynamic_axes=axes,
            opset_version=opset,
            do_constant_folding=True,
            dynamo=False,
        )
    return buffer.getvalue()
