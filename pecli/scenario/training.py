"""The training section of a scenario: the learner, its belief, the curriculum and self-play (paper §IV, §V-A)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from pecli.roles import Role
from pecli.scenario.values import (
    MAX_BATCH,
    MAX_BUFFER,
    MAX_COUNT,
    MAX_DEPTH,
    MAX_GAMES,
    MAX_HISTORY,
    MAX_STEPS,
    MAX_WIDTH,
    Count,
    Real,
    _Model,
)


class Curriculum(_Model):
    """Paper section V-A: over the first ``fraction`` of training the pursuer's FOV shrinks from 2pi
    to its configured value and the evader's speed limit grows from 0 to its configured value."""

    enabled: bool = True
    fraction: Real = Field(default=0.3, gt=0, le=1, description="share of the training budget it spans")
    steps: Count | None = Field(
        default=None,
        ge=1,
        le=MAX_STEPS,
        description="learner transitions it spans, instead of a fraction of the budget "
        "(for runs a CPU budget stops, whose planned budget is only a ceiling)",
    )

    def span(self, budget: int) -> float:
        """The learner transitions the curriculum spans in a run planned for ``budget`` of them."""
        return float(self.steps) if self.steps is not None else max(1.0, self.fraction * budget)


class BeliefSettings(_Model):
    """The belief network and how it is fitted (paper section V-A)."""

    hidden: Count = Field(default=128, ge=1, le=MAX_WIDTH, description="BiMDN LSTM units per direction")
    fc: Count = Field(default=32, ge=1, le=MAX_WIDTH, description="width of the shared layer and of each head")
    components: Count = Field(default=3, ge=1, le=1024, description="Gaussians in the mixture")
    samples: Count = Field(default=16, ge=1, le=MAX_BATCH, description="draws the 'bimdn-mixed' actor reads")
    buffer_size: Count = Field(default=25_000, ge=1, le=MAX_BUFFER, description="(window, true position) pairs kept")
    warmup: Count = Field(default=10_000, ge=0, le=MAX_STEPS, description="pairs collected before fitting starts")
    update_every: Count = Field(default=10, ge=1, le=MAX_COUNT, description="vector-env steps between belief updates")
    batch_size: Count = Field(default=256, ge=1, le=MAX_BATCH)
    learning_rate: Real = Field(default=0.002, gt=0)
    max_grad_norm: Real = Field(default=1.0, gt=0, description="(ours) gradient clipping of the belief's updates")


class SelfPlay(_Model):
    """Alternating self-play (``pecli selfplay``): each round trains the pursuer, then the evader,
    against opponents drawn from the other side's pool."""

    rounds: Count = Field(default=10, ge=1, le=100_000, description="rounds; a round trains each side once")
    steps_per_round: Count = Field(
        default=50_000, ge=1, le=MAX_STEPS, description="learner transitions per side per round"
    )
    schedule: Literal["alternating", "simultaneous"] = Field(
        default="alternating",
        description="alternating: one side trains at a time against the other's pool; simultaneous: both "
        "learners in the same games, both learning every step (the paper's MADDPG)",
    )
    opponents: Literal["latest", "uniform", "pfsp", "league", "nash"] = Field(
        default="pfsp",
        description="latest: the newest opponents; uniform: the whole pool; pfsp: weighted by how often they win; "
        "league: pfsp with exploiters and the scripted players kept in the pool (AlphaStar's league); nash: the "
        "league with the Nash mixture of the pools' meta-game in place of pfsp (PSRO's meta-solver)",
    )
    nash_games: int = Field(
        default=100,
        ge=1,
        le=100_000,
        description="(ours) nash: games each new pairing of the two pools plays for the meta-game's capture matrix "
        "(its CPU counts in the run's budget)",
    )
    pfsp_power: Real = Field(default=2.0, gt=0, description="(ours) PFSP weight = P(opponent wins)^power")
    pfsp_prior_episodes: Real = Field(
        default=10.0, gt=0, description="(ours) pseudo-episodes of the prior (a tournament's prediction, else 0.5)"
    )
    pfsp_decay: Real = Field(
        default=0.5,
        ge=0,
        le=1,
        description="(ours) share of an opponent's record kept when the learner moves on a round",
    )
    league_floor: Real = Field(
        default=0.2, ge=0, le=1, description="(ours) league: the share of games the scripted players keep, together"
    )
    league_floor_split: Literal["uniform", "pfsp"] = Field(
        default="uniform",
        description="(ours) league: the floor split among the scripted players alike (uniform), or by their pfsp "
        "weights, most to those that still beat the learner (pfsp)",
    )
    league_exploiter_share: Real = Field(
        default=0.0,
        ge=0,
        le=1,
        description="(ours) league: the share of games the exploiters that joined the pool keep, together, split by "
        "their pfsp weights (AlphaStar's main agents spend games on the league's exploiters); 0: they are drawn by "
        "pfsp like any other checkpoint",
    )
    league_exploiter_every: int = Field(
        default=1,
        ge=0,
        le=100_000,
        description="(ours) league: the exploiters train in every k-th round (1: every round, as AlphaStar's; 0: "
        "never, the main agents' pools keep only the scripted players and their own checkpoints)",
    )
    league_exploiter_roles: list[Role] = Field(
        default=["pursuer", "evader"],
        min_length=1,
        description="(ours) league: the sides that have an exploiter (an evader exploiter finds the main pursuer's "
        "holes, a pursuer exploiter the main evader's)",
    )
    league_exploiter_after: Real = Field(
        default=0.0,
        ge=0,
        le=100_000,
        description="(ours) league: CPU-hours the run spends before its exploiters train (a run of hours can leave "
        "its first hours to the main agents and call the exploiters in once what is left to find are holes)",
    )
    exploiter_join: Real = Field(
        default=0.5,
        gt=0,
        le=1,
        description="(ours) league: an exploiter joins its side's pool when it wins this share of its turn's games "
        "(or of its join games, with exploiter_join_games)",
    )
    exploiter_join_games: int = Field(
        default=0,
        ge=0,
        le=100_000,
        description="(ours) league: N > 0: after its turn the exploiter's final network plays N games against the "
        "main agent it trained against, and these decide whether it joins (AlphaStar's exploiters join on their win "
        "rate against the main agents); 0: its record over the whole turn, learning included, decides",
    )
    league_exploiter_timeout: int = Field(
        default=0,
        ge=0,
        le=100_000,
        description="(ours) league: an exploiter joins its side's pool at the end of its k-th turn without joining, "
        "whatever it won (AlphaStar's timeout), and starts afresh; 0: it joins only by winning exploiter_join",
    )

    average_last: int = Field(
        default=10,
        ge=0,
        le=100_000,
        description="(ours) after every round each main learner's average.zip is the mean of the weights of its "
        "last k rounds played after the curriculum (fewer while the run is younger; the newest round alone while "
        "the curriculum runs), the player a run hands over; 0: none",
    )

    @model_validator(mode="after")
    def _league_alternates(self) -> SelfPlay:
        if self.opponents in ("league", "nash") and self.schedule != "alternating":
            raise ValueError(
                f"opponents '{self.opponents}' needs the alternating schedule (the simultaneous one has no pools)"
            )
        if self.league_floor + self.league_exploiter_share > 1:
            raise ValueError(
                f"league_floor ({self.league_floor}) and league_exploiter_share "
                f"({self.league_exploiter_share}) together keep more than all the games"
            )
        return self


ALGOS = ("td3", "ddpg", "sac", "tqc", "crossq")  # the algorithms of pecli.models.algorithms


class Training(_Model):
    """How a learner is trained (Stable-Baselines3 / sb3-contrib off-policy algorithms on a frozen-opponent view)."""

    algo: Literal[ALGOS] = Field(default="td3", description="td3, ddpg, sac, tqc or crossq")  # type: ignore[valid-type]
    belief: Literal["none", "bimdn", "bimdn-mixed", "ukf", "image"] = Field(
        default="none", description="what the actor adds to its observation about the unseen opponent"
    )
    steps: Count = Field(
        default=1_000_000, ge=1, le=MAX_STEPS, description="budget in learner transitions (all envs together)"
    )
    n_envs: Count = Field(default=8, ge=1, le=MAX_COUNT, description="games stepped together in one process")
    frame_skip: Count = Field(default=2, ge=1, le=1000, description="game steps each action is held for")
    frame_stack: Count = Field(default=2, ge=1, le=1000, description="observations stacked into the actor's input")
    history_length: Count = Field(
        default=200, ge=1, le=MAX_HISTORY, description="game steps the belief window looks back"
    )
    history_stride: Count = Field(
        default=10, ge=1, le=MAX_HISTORY, description="keep every k-th step of the window (10: 1 Hz)"
    )
    reward_scale: Real = Field(default=0.001, gt=0, description="rewards are multiplied by this for learning")
    learning_rate: Real = Field(default=5e-4, gt=0)
    buffer_size: Count = Field(default=100_000, ge=1, le=MAX_BUFFER)
    batch_size: Count = Field(default=512, ge=1, le=MAX_BATCH)
    gamma: Real = Field(default=0.99, gt=0, le=1)
    tau: Real = Field(default=0.005, gt=0, le=1)
    n_step: Count = Field(
        default=1, ge=1, le=1000, description="n-step returns: rewards summed over n transitions before bootstrapping"
    )
    action_noise: Real = Field(default=0.1, ge=0, description="std of the Gaussian exploration noise")
    net_arch: list[Annotated[Count, Field(ge=1, le=MAX_WIDTH)]] = Field(
        default=[128, 128], min_length=1, max_length=MAX_DEPTH, description="hidden layer widths of actor and critics"
    )
    learning_starts: Count = Field(
        default=5_000, ge=0, le=MAX_STEPS, description="transitions collected before learning"
    )
    train_freq: Count = Field(default=1, ge=1, le=MAX_COUNT, description="vector-env steps between updates")
    gradient_steps: Count = Field(default=2, ge=1, le=10_000, description="gradient steps per update")
    checkpoint_every: Count = Field(default=250, ge=1, le=MAX_COUNT, description="episodes between zoo checkpoints")
    eval_every: Count = Field(default=0, ge=0, le=MAX_STEPS, description="transitions between evaluations; 0: none")
    eval_episodes: Count = Field(default=200, ge=1, le=MAX_GAMES)
    torch_threads: Count = Field(
        default=1, ge=1, le=1024, description="torch threads per process (1 is fastest on a shared CPU)"
    )
    curriculum: Curriculum = Curriculum()
    belief_settings: BeliefSettings = BeliefSettings()
    selfplay: SelfPlay = SelfPlay()

    @model_validator(mode="after")
    def _window_fits(self) -> Training:
        if self.history_stride > self.history_length:
            raise ValueError(
                f"history_stride ({self.history_stride}) must not exceed history_length ({self.history_length})"
            )
        return self
