"""Many learned players of one network shape, decided in one pass: their weights stacked, their games batched.

Self-play's opponents are a pool of checkpoints of one learner, and each batched game draws its own (see
:class:`~pecli.policies.mixed.MixedPolicy`), so a step holds many members with a game or two each. Run one by
one, each costs a whole network call for those few rows: with a BiMDN belief, a bidirectional LSTM over the
window for each member, about a millisecond however few rows it has. :class:`StackedActors` instead stacks the
members' parameters (``(members, ...)``, a copy taken when the stack is built: pool members are frozen) and runs
every game deciding in a step at once, each with its member's weights: one batched matrix product per layer and
per LSTM time step, whatever the number of members. With few members deciding, their own calls are cheaper
(``WORTH_STACKING``), and so is a member's own call with many games (each game's row gathers its member's
weights: ``MAX_GAMES_PER_MEMBER``); :class:`~pecli.policies.mixed.MixedPolicy` then lets them decide alone.

It covers the deterministic actors of off-policy checkpoints built of ``Linear``, ``ReLU`` and ``Tanh`` layers
(TD3 and DDPG; SAC's and TQC's squashed mean), without a belief or with a ``bimdn``, ``ukf`` or ``image`` one. The
UKF has no weights, so one filter runs over every deciding game's window; the image beliefs' CNNs run as one
grouped convolution, a group per game with its member's kernels. Players of other kinds (a ``bimdn-mixed`` belief,
CrossQ's batch renormalisation, an ONNX export, scripted ones) keep deciding on their own. The results equal the
members' own up to float rounding (about 1e-6).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch as th
import torch.nn.functional as F
from torch import nn

from pecli.belief.bimdn import BiMDN
from pecli.belief.image import ImageBelief, rasterise
from pecli.belief.model import BeliefModel
from pecli.models.algorithms import deterministic_actor
from pecli.models.extractors import BeliefExtractor, KeysExtractor
from pecli.policies.learned import LearnedPolicy

# how many members must decide in one step for deciding together to be cheaper than one by one (one CPU core,
# benchmarks/bench_opponents.py): below it, they decide on their own
WORTH_STACKING = {"none": 4, "bimdn": 4, "ukf": 2, "image": 2}
# and at most this many deciding games per member on average: each game's row gathers its member's weights, so with
# many games per member their own batched calls are cheaper, the sooner the larger the network (ten members, 32 games:
# 0.67x without a belief, 0.79x with a 64-unit BiMDN, 1.4x with 128 units; self-play's 16 among ten: 1.6). The UKF
# gathers no weights (two members with 32 games each: 0.95x; ten among 16 games: 0.25x); the image CNN's grouped
# convolutions do (two with 32 games each: 1.1x, four with 16: 0.85x; ten among 16 games: 0.32x)
MAX_GAMES_PER_MEMBER = {"none": 4.0, "bimdn": 2.0, "ukf": 64.0, "image": 16.0}
Stack = list[tuple[str, th.Tensor | None, th.Tensor | None]]  # ("linear", W (M, out, in), b (M, out)) or an activation
ACTIVATIONS = {nn.ReLU: "relu", nn.Tanh: "tanh"}


def _layers(module: nn.Module) -> list[nn.Module] | None:
    """``module`` as a flat list of Linear / ReLU / Tanh layers, or ``None`` if it holds anything else."""
    if isinstance(module, nn.Sequential):
        flat: list[nn.Module] = []
        for child in module:
            inner = _layers(child)
            if inner is None:
                return None
            flat += inner
        return flat
    if isinstance(module, nn.Linear) and module.bias is None:
        return None
    return [module] if isinstance(module, (nn.Linear, *ACTIVATIONS)) else None


def _stack_layers(networks: Sequence[list[nn.Module]]) -> Stack:
    """One stacked layer per position of ``networks`` (flat lists of one shape)."""
    stack: Stack = []
    for layer in zip(*networks):
        if isinstance(layer[0], nn.Linear):
            stack.append(
                ("linear", th.stack([m.weight.detach() for m in layer]), th.stack([m.bias.detach() for m in layer]))
            )
        else:
            stack.append((ACTIVATIONS[type(layer[0])], None, None))
    return stack


def _run_layers(stack: Stack, x: th.Tensor, members: th.Tensor) -> th.Tensor:
    """``x`` ``(m, B, in)`` through the stacked layers of the ``members`` (indices, ``(m,)``)."""
    for kind, weight, bias in stack:
        if kind == "linear":
            x = th.baddbmm(bias[members].unsqueeze(1), x, weight[members].transpose(1, 2))
        else:
            x = th.relu(x) if kind == "relu" else th.tanh(x)
    return x


def _signature(layers: list[nn.Module]) -> tuple:
    """The layers' kinds and weight shapes: what networks must share to stack."""
    return tuple((type(m).__name__, tuple(m.weight.shape) if isinstance(m, nn.Linear) else ()) for m in layers)


MEAN_HEADS = ("weight_head", "mean_head")  # what a mixture's mean needs of its head (not the stds)


def _stack_heads(heads: Sequence[nn.Module]) -> dict[str, Stack]:
    """The mixture heads' weight and mean layers (:class:`~pecli.belief.bimdn.MixtureHead`), stacked."""
    return {name: _stack_layers([list(getattr(head, name)) for head in heads]) for name in MEAN_HEADS}


def _head_signature(head: nn.Module) -> tuple:
    """What mixture heads must share to stack."""
    return tuple(_signature(list(getattr(head, name))) for name in MEAN_HEADS)


class _StackedBiMDN:
    """The BiMDNs of several members stacked: windows ``(m, B, T, d)`` → the mixtures' means ``(m, B, 2)``."""

    def __init__(self, nets: Sequence[BiMDN]) -> None:
        def weights(name: str) -> th.Tensor:  # (2M, ...): every member's forward direction, then every reverse one
            return th.stack([getattr(net.lstm, name + suffix).detach() for suffix in ("", "_reverse") for net in nets])

        self.w_ih = weights("weight_ih_l0").transpose(1, 2).contiguous()  # (2M, d, 4H)
        self.w_hh = weights("weight_hh_l0").transpose(1, 2).contiguous()  # (2M, H, 4H)
        self.bias = weights("bias_ih_l0") + weights("bias_hh_l0")
        self.hidden, self.count = nets[0].lstm.hidden_size, len(nets)
        self.trunk = _stack_layers([list(net.trunk) for net in nets])
        self.heads = _stack_heads([net.head for net in nets])
        self.components = nets[0].components

    def means(self, windows: th.Tensor, members: th.Tensor) -> th.Tensor:
        m, batch, steps, _ = windows.shape
        both = th.cat([members, members + self.count])  # the rows of (2M, ...) holding these members' directions
        inputs = th.cat([windows, windows.flip(2)])  # the reverse direction reads the window backwards
        gates_in = (
            th.baddbmm(self.bias[both].unsqueeze(1), inputs.reshape(2 * m, batch * steps, -1), self.w_ih[both])
            .view(2 * m, batch, steps, -1)
            .transpose(0, 2)
            .contiguous()
        )
        w_hh = self.w_hh[both]
        h = windows.new_zeros(2 * m, batch, self.hidden)
        c = th.zeros_like(h)
        cell = slice(2 * self.hidden, 3 * self.hidden)
        for t in range(steps):  # PyTorch's gate order: input, forget, cell, output
            gates = th.baddbmm(gates_in[t].transpose(0, 1), h, w_hh)
            g = th.tanh(gates[:, :, cell])
            i, f, _, o = th.sigmoid(gates).chunk(4, dim=2)
            c = th.addcmul(f * c, i, g)
            h = o * th.tanh(c)
        z = _run_layers(self.trunk, th.cat([h[:m], h[m:]], dim=2), members)  # as BiMDN: [forward end, backward end]
        logits = _run_layers(self.heads["weight_head"], z, members)
        means = _run_layers(self.heads["mean_head"], z, members).view(m, batch, self.components, 2)
        return _mixture_mean(logits, means)


def _mixture_mean(logits: th.Tensor, means: th.Tensor) -> th.Tensor:
    """:meth:`Mixture.mean` of stacked heads: logits ``(m, B, K)``, means ``(m, B, K, 2)`` → ``(m, B, 2)``."""
    return (th.softmax(logits, dim=2).unsqueeze(-1) * means).sum(2)


class _StackedUKF:
    """The UKF beliefs of several members (no weights: one filter over all their windows)."""

    def __init__(self, beliefs: Sequence[BeliefModel]) -> None:
        self.ukf = beliefs[0].ukf

    def means(self, windows: th.Tensor, members: th.Tensor) -> th.Tensor:
        m, batch = windows.shape[:2]
        mixture = self.ukf(windows.reshape(m * batch, -1).numpy())
        return mixture.means[:, 0].view(m, batch, 2)


def _cnn_layers(net: ImageBelief) -> tuple[list[nn.Conv2d], list[nn.Module]] | None:
    """The image belief's two 3 x 3 convolutions and its dense layers, if its CNN has the built-in layout."""
    layers = list(net.cnn)
    kinds = [nn.Conv2d, nn.ReLU, nn.MaxPool2d, nn.Conv2d, nn.ReLU, nn.MaxPool2d, nn.Flatten]
    if len(layers) < len(kinds) or not all(type(layer) is kind for layer, kind in zip(layers, kinds)):
        return None
    convs: list[nn.Conv2d] = [layers[0], layers[3]]  # type: ignore[list-item]
    for conv in convs:
        if conv.bias is None or conv.stride != (1, 1) or conv.padding != (1, 1) or conv.groups != 1:
            return None
    for pool in (layers[2], layers[5]):
        if pool.kernel_size != 2 or pool.stride != 2 or pool.padding != 0:
            return None
    dense = _layers(nn.Sequential(*layers[len(kinds) :]))
    return None if dense is None else (convs, dense)


class _StackedImage:
    """The image beliefs of several members: one rasterising pass, their CNNs as grouped convolutions."""

    def __init__(self, beliefs: Sequence[BeliefModel]) -> None:
        nets: list[ImageBelief] = [b.net for b in beliefs]  # type: ignore[misc]
        cnns = [cnn for cnn in map(_cnn_layers, nets) if cnn is not None]
        if len(cnns) != len(nets):
            raise ValueError("image beliefs stack only with the built-in CNN layout")
        self.decoder, self.grid = nets[0].decoder, nets[0].grid
        self.convs = [  # each convolution's kernels (M, out, in, 3, 3) and biases (M, out)
            (th.stack([c.weight.detach() for c in layer]), th.stack([th.as_tensor(c.bias).detach() for c in layer]))
            for layer in zip(*(convs for convs, _ in cnns))
        ]
        self.dense = _stack_layers([dense for _, dense in cnns])
        self.heads = _stack_heads([net.head for net in nets])
        self.components = nets[0].head.components

    def means(self, windows: th.Tensor, members: th.Tensor) -> th.Tensor:
        m, batch = windows.shape[:2]
        rows = th.repeat_interleave(members, batch)  # each window's member
        images = rasterise(self.decoder(windows.reshape(m * batch, -1).numpy()), self.decoder, self.grid)
        x = th.as_tensor(images).reshape(1, -1, self.grid, self.grid)  # one group of 3 channels per window
        for weight, bias in self.convs:
            kernels = weight[rows]  # (R, out, in, 3, 3)
            x = F.conv2d(x, kernels.flatten(0, 1), bias[rows].flatten(), padding=1, groups=len(rows))
            x = F.max_pool2d(th.relu(x), 2)
        z = _run_layers(self.dense, x.reshape(len(rows), 1, -1), rows)  # Flatten: (channels, height, width)
        logits = _run_layers(self.heads["weight_head"], z, rows)
        means = _run_layers(self.heads["mean_head"], z, rows).view(len(rows), 1, self.components, 2)
        return _mixture_mean(logits, means).view(m, batch, 2)


def _stacked_belief(kind: str, beliefs: Sequence[BeliefModel]) -> _StackedBiMDN | _StackedUKF | _StackedImage | None:
    """The stacked belief of members whose beliefs are of ``kind`` (``None`` without one)."""
    if kind == "none":
        return None
    if kind == "bimdn":
        return _StackedBiMDN([b.net for b in beliefs])  # type: ignore[misc]
    return _StackedUKF(beliefs) if kind == "ukf" else _StackedImage(beliefs)


class StackedActors:
    """The deterministic actors of ``members`` (learned players of one network shape) run together.

    Build it with :meth:`of`, which says which players it can take; :meth:`decide` then plays any of them
    at once. The members' memories (frame stacks, windows, decision clocks) stay their own.
    """

    def __init__(self, members: Sequence[LearnedPolicy]) -> None:
        actors = [_layers(deterministic_actor(member.actor)) for member in members]
        self.actor = _stack_layers(actors)  # type: ignore[arg-type]
        beliefs = [member._belief for member in members]
        kind = "none" if beliefs[0] is None else beliefs[0].kind
        self.belief = _stacked_belief(kind, beliefs)  # type: ignore[arg-type]
        self.frame = beliefs[0].frame if beliefs[0] is not None else None
        self.window = beliefs[0].window if beliefs[0] is not None else None
        self.worth, self.games_per_member = WORTH_STACKING[kind], MAX_GAMES_PER_MEMBER[kind]

    def worth_it(self, members: int, games: int) -> bool:
        """Whether ``members`` deciding for ``games`` games in all decide faster together than one by one."""
        return members >= self.worth and games <= self.games_per_member * members

    @staticmethod
    def key(member: object) -> tuple | None:
        """What members must share to stack (``None``: ``member`` decides on its own)."""
        if not isinstance(member, LearnedPolicy) or member.actor.device.type != "cpu":
            return None
        extractor = member.actor.features_extractor
        if not (
            isinstance(extractor, BeliefExtractor)
            or (isinstance(extractor, KeysExtractor) and extractor.keys == ("obs",))
        ):
            return None
        layers = _layers(deterministic_actor(member.actor))
        if layers is None:
            return None
        belief = member._belief
        if belief is None:
            return ("none", _signature(layers))
        frame = belief.frame
        shared = (_signature(layers), belief.window, frame.frame, frame.half, frame.inverse_range, frame.heading_index)
        if belief.kind == "ukf":
            return ("ukf", *shared, belief.decoder.scenario.model_dump_json())
        if belief.kind == "image" and isinstance(belief.net, ImageBelief):
            image = belief.net
            cnn = _cnn_layers(image)
            if cnn is None:
                return None
            convs = tuple(tuple(conv.weight.shape) for conv in cnn[0])
            scenario = image.decoder.scenario.model_dump_json()
            return ("image", *shared, convs, _signature(cnn[1]), _head_signature(image.head), image.grid, scenario)
        if (
            belief.kind != "bimdn"
            or not isinstance(belief.net, BiMDN)
            or belief.net.lstm.num_layers != 1
            or not belief.net.lstm.bidirectional
            or not belief.net.lstm.batch_first
        ):
            return None
        net = belief.net
        heads = _head_signature(net.head)
        return ("bimdn", *shared, net.lstm.hidden_size, net.components, _signature(list(net.trunk)), heads)

    @classmethod
    def of(cls, members: Sequence[object]) -> dict[int, tuple[StackedActors, int]]:
        """Stacks for the members that share a shape with another: ``{member index: (stack, its row)}``."""
        groups: dict[tuple, list[int]] = {}
        for index, member in enumerate(members):
            key = cls.key(member)
            if key is not None:
                groups.setdefault(key, []).append(index)
        placed: dict[int, tuple[StackedActors, int]] = {}
        for indices in groups.values():
            if len(indices) > 1:
                stack = cls([members[i] for i in indices])  # type: ignore[misc]
                placed.update({index: (stack, row) for row, index in enumerate(indices)})
        return placed

    @th.no_grad()
    def decide(
        self, rows: Sequence[int], stacks: Sequence[np.ndarray], histories: Sequence[np.ndarray | None]
    ) -> list[np.ndarray]:
        """Actions ``(d_j, 2)`` of the members at stacked ``rows`` for their deciding games: frame stacks
        ``(d_j, k * dim)`` and (with a belief) windows ``(d_j, samples * dim)``."""
        sizes = [len(stack) for stack in stacks]
        members = th.as_tensor(np.repeat(np.asarray(rows, dtype=np.int64), sizes))  # one per game: (R,)
        obs = th.as_tensor(np.concatenate(stacks)).unsqueeze(1)  # (R, 1, k * dim)
        if self.belief is not None:
            windows = th.as_tensor(np.concatenate(histories)).view(len(members), 1, *self.window)  # type: ignore
            points = self.belief.means(windows, members)
            features = self.frame(points.view(-1, 2), windows[:, 0, -1])
            obs = th.cat([obs, features.unsqueeze(1)], dim=2)
        actions = _run_layers(self.actor, obs, members).view(-1, 2).numpy()
        return np.split(actions, np.cumsum(sizes)[:-1])
