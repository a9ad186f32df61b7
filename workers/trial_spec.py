"""Provides `TrialSpec`: one trial's settings, checked where they enter, and the optimizer
they describe."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from linkevo.sim.errors import LinkevoError
from linkevo.sim.robot.hexapod import ROBOT_PARTS, Robot
from linkevo.sim.study import (
    APPROACHES,
    CANDIDATES_PER_WALK,
    DEFAULT_ANGLES,
    DEFAULT_BATCH,
    DEFAULT_WALK_BATCH,
    MAP_ELITES,
    MAX_WALKS,
    MIN_ANGLES,
    MODES,
    MULTI_OBJECTIVE,
    SAIL_APPROACHES,
    SINGLE_FITNESSES,
    SURROGATES,
    TARGETS,
    WALKING_FITNESS,
    evaluated_fitness,
    is_map_elites,
)

if TYPE_CHECKING:
    from linkevo.algorithms import Optimizer
    from linkevo.sim.linkage.fitness import Target


class TrialSpecError(LinkevoError, ValueError):
    """A trial setting that is not allowed; the message names the value and the choices."""


def _is_int(value: object) -> bool:
    return isinstance(value, int | np.integer) and not isinstance(value, bool)


@dataclass(frozen=True)
class TrialSpec:
    """One trial: which search, on which loss, for how many evaluations.

    Attributes:
        approach: one of `sim.study.APPROACHES`.
        fitness: "Fp" or "Fsl" (NSGA-II evaluates the two-objective variant).
        evaluations: the budget; the trial runs whole batches while they fit in it (the
            initial population counts), so it must be >= batch_size.
        batch_size: children per iteration and initial population size.
        mode: "paper" or "legacy".
        seed: seed of the optimizer (>= 0).
        target: F_p target: "D16", "D24" or a JSON target file.
        n_angles: crank angles per turn (>= `sim.study.MIN_ANGLES`).
        checkpoint_every: iterations between checkpoints (>= 1).
        max_seconds: optional wall-clock limit of one `run_trial` call, checked after each
            iteration (so at least one runs).
        options: approach-specific settings passed to `algorithms.make_optimizer`.
        walk_rerank: walk this many of the final lowest-loss linkages that pass the physical
            checks on the simulated robot (`workers.trial_walks.rerank_by_walking`); 0: none.
        walks: the budget of a walking trial (fitness "Fw"): candidates walked on the
            physics (`sim.robot.walk_fitness`); the trial ends once it has walked this many, or
            after `evaluations` candidates, a guard (`CANDIDATES_PER_WALK` per walk when
            built with `walking`). 0 for the path fitnesses.
        seed_from: a walking MAP-Elites trial's warm start: the run id of an earlier
            MAP-Elites trial whose repertoire and walk map make the first batch
            (`workers.seed_repertoire`); "" for none.
        surrogate: how a walking MAP-Elites trial uses the learned walk model: "" not at
            all; "screen" walks only the candidates the model, fitted on its walks as it
            goes, predicts could enter or improve its archive (`workers.walk_surrogate`);
            "sail" runs the search in the model and walks what it proposes (SAIL,
            `workers.walk_sail`). true and false stand for "screen" and "".
        walk_model: a SAIL trial's head start: the run id of a fitted walk model (`linkevo
            walkmodel fit`); "" for none.
        physics: the simulated robot's parameters that differ from the study's robot
            (`sim.robot.hexapod.Physics`), for every walk of the trial (F_w's, `walk_rerank`'s).
        gait: the gait's settings that differ from the study's (`sim.robot.gait.GaitConfig`).
        phases: each leg slot's phase offset (degrees) where it differs from the study's
            tripods (a robot config's motors, `sim.robot.hexapod.Robot`).
        mounting: each slot's spacer layers (a robot config's `[mounting]`, all six); empty:
            chosen for each linkage (`sim.robot.mounting.auto_spacers`).

    Raises:
        TrialSpecError: on construction, for any value outside the allowed ones.
    """

    approach: str
    fitness: str
    evaluations: int
    batch_size: int = DEFAULT_BATCH
    mode: str = "paper"
    seed: int = 0
    target: str = "D16"
    n_angles: int = DEFAULT_ANGLES
    checkpoint_every: int = 10
    max_seconds: float | None = None
    options: dict = field(default_factory=dict)
    walk_rerank: int = 0
    walks: int = 0
    seed_from: str = ""
    surrogate: str = ""
    walk_model: str = ""
    physics: dict = field(default_factory=dict)
    gait: dict = field(default_factory=dict)
    phases: dict = field(default_factory=dict)
    mounting: dict = field(default_factory=dict)

    @classmethod
    def walking(cls, approach: str, walks: int, **settings: object) -> TrialSpec:
        """Returns a walking trial ("Fw") of `walks` walked candidates, `DEFAULT_WALK_BATCH`
        candidates per iteration and at most `CANDIDATES_PER_WALK` per walk (unless
        `batch_size` or `evaluations` say otherwise)."""
        if not _is_int(walks) or not 1 <= walks <= MAX_WALKS:
            raise TrialSpecError(f"walks must be an integer in [1, {MAX_WALKS:,}], got {walks!r}")
        settings.setdefault("batch_size", DEFAULT_WALK_BATCH)
        settings.setdefault("evaluations", max(walks * CANDIDATES_PER_WALK, settings["batch_size"]))
        return cls(approach, WALKING_FITNESS, walks=walks, **settings)  # type: ignore[arg-type]

    def __post_init__(self) -> None:
        def fail(message: str) -> None:
            raise TrialSpecError(message)

        if self.approach not in APPROACHES:
            fail(f"unknown approach {self.approach!r}; allowed: {', '.join(APPROACHES)}")
        if self.fitness not in SINGLE_FITNESSES:
            fail(f"unknown fitness {self.fitness!r}; allowed: {', '.join(SINGLE_FITNESSES)}")
        if self.mode not in MODES:
            fail(f"unknown mode {self.mode!r}; allowed: {', '.join(MODES)}")
        if not _is_int(self.batch_size) or self.batch_size < 1:
            fail(f"batch size must be a positive integer, got {self.batch_size!r}")
        if not _is_int(self.evaluations) or self.evaluations < self.batch_size:
            fail(
                f"evaluations must be an integer >= the batch size ({self.batch_size}), "
                f"got {self.evaluations!r}"
            )
        if not _is_int(self.seed) or self.seed < 0:
            fail(f"seed must be a non-negative integer, got {self.seed!r}")
        if not _is_int(self.n_angles) or self.n_angles < MIN_ANGLES:
            fail(f"n_angles must be an integer >= {MIN_ANGLES}, got {self.n_angles!r}")
        if not _is_int(self.walk_rerank) or self.walk_rerank < 0:
            fail(f"walk_rerank must be an integer >= 0, got {self.walk_rerank!r}")
        if self.fitness == WALKING_FITNESS:
            if not _is_int(self.walks) or not 1 <= self.walks <= MAX_WALKS:
                allowed = f"an integer in [1, {MAX_WALKS:,}]"
                fail(f"walks must be {allowed} for fitness Fw, got {self.walks!r}")
            if self.walk_rerank:
                fail("walk_rerank is for the path fitnesses: an Fw trial walks every candidate")
        elif self.walks != 0:
            fail(f"walks = {self.walks!r} is for fitness Fw only (this trial is {self.fitness})")
        if self.seed_from and not (self.walking_trial and is_map_elites(self.approach)):
            fail(
                f"seed_from = {self.seed_from!r} is for walking trials of a MAP-Elites "
                f"approach ({', '.join(MAP_ELITES)}), not {self.approach} with {self.fitness}"
            )
        if isinstance(self.surrogate, bool):
            object.__setattr__(self, "surrogate", "screen" if self.surrogate else "")
        if self.surrogate not in SURROGATES:
            fail(
                f"surrogate must be one of {', '.join(map(repr, SURROGATES))}, "
                f"got {self.surrogate!r}"
            )
        if self.surrogate and not (self.walking_trial and is_map_elites(self.approach)):
            fail(
                f"surrogate = {self.surrogate!r} is for walking trials of a MAP-Elites approach "
                f"({', '.join(MAP_ELITES)}), not {self.approach} with {self.fitness}"
            )
        if self.surrogate == "screen":
            from linkevo.workers.walk_surrogate import START

            if self.walks <= START:
                fail(
                    f"surrogate = 'screen' with walks = {self.walks}: the walk model is first "
                    f"fitted after {START} walks, so it would screen none; allowed: walks > {START}"
                )
        if self.surrogate == "sail" and self.approach not in SAIL_APPROACHES:
            fail(
                f"surrogate = 'sail' runs {', '.join(SAIL_APPROACHES)}, not {self.approach} "
                "(its descriptors are learned from the archive it fills)"
            )
        if self.surrogate == "sail" and not self.walk_model:
            from linkevo.workers.walk_sail import START as SAIL_START

            if self.walks <= SAIL_START:
                fail(
                    f"surrogate = 'sail' with walks = {self.walks} and no walk_model: the walk "
                    f"model is first fitted after {SAIL_START} walks, so it would propose none; "
                    f"allowed: walks > {SAIL_START}, or a head start (walk_model)"
                )
        if not isinstance(self.walk_model, str):
            fail(f"walk_model must be a walk model's run id (a string), got {self.walk_model!r}")
        if self.walk_model and self.surrogate != "sail":
            fail(
                f"walk_model = {self.walk_model!r} is a SAIL trial's head start: "
                "set surrogate = 'sail'"
            )
        for part in ROBOT_PARTS:
            if not isinstance(getattr(self, part), dict):
                fail(f"{part} must be a table of numbers, got {getattr(self, part)!r}")
        try:
            self.robot()
        except (TypeError, ValueError) as exc:
            fail(str(exc))
        if not _is_int(self.checkpoint_every) or self.checkpoint_every < 1:
            fail(f"checkpoint_every must be a positive integer, got {self.checkpoint_every!r}")
        if self.max_seconds is not None and not (
            isinstance(self.max_seconds, int | float) and self.max_seconds > 0
        ):
            fail(f"max_seconds must be a positive number or None, got {self.max_seconds!r}")
        if not isinstance(self.options, dict):
            fail(f"options must be a dict, got {self.options!r}")
        try:
            json.dumps(self.options)
        except TypeError as exc:
            fail(f"options must be JSON-able ({exc}), got {self.options!r}")
        try:
            resolve_target(self.target)
        except ValueError as exc:
            fail(str(exc))

    def robot(self) -> Robot:
        """Returns the robot the trial's walks walk (`physics`, `gait`, `phases` and
        `mounting`)."""
        return Robot.of({part: getattr(self, part) for part in ROBOT_PARTS})

    @property
    def walking_trial(self) -> bool:
        """Whether the trial's loss comes from walking (fitness "Fw")."""
        return self.fitness == WALKING_FITNESS

    @property
    def eval_fitness(self) -> str:
        """The `sim.linkage.evaluating` fitness the evaluator must use ("Fp2"/"Fsl2" for NSGA2)."""
        return evaluated_fitness(self.fitness, self.approach in MULTI_OBJECTIVE)

    @property
    def iterations(self) -> int:
        """Iterations the budget allows (the initial population is the first)."""
        return self.evaluations // self.batch_size

    def to_dict(self) -> dict[str, object]:
        """Returns the JSON-able fields; `surrogate` "" and "screen" as false and true and
        an empty `walk_model` left out, as linkevo wrote them before SAIL (their
        checkpoints resume)."""
        out = asdict(self)
        out["surrogate"] = {"": False, "screen": True}.get(self.surrogate, self.surrogate)
        if not self.walk_model:
            del out["walk_model"]
        return out


def resolve_target(target: str) -> Target:
    """Returns the F_p target named `target` ("D16", "D24") or stored in a JSON file.

    Raises:
        TrialSpecError: naming the value when it is neither a published name nor a
            readable JSON target file.
    """
    from linkevo.sim.linkage.fitness import Target, named_target

    if target in TARGETS:
        return named_target(target)
    path = Path(target)
    if not path.is_file():
        raise TrialSpecError(
            f"target {target!r} is neither a published target ({', '.join(TARGETS)}) "
            "nor an existing JSON file"
        )
    try:
        doc = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise TrialSpecError(f"target file {target!r} is not readable JSON: {exc}") from exc
    try:
        return Target.from_dict(doc, name=path.stem)
    except (KeyError, TypeError, ValueError) as exc:
        raise TrialSpecError(f"target file {target!r} is not a target ({exc})") from exc


def build_optimizer(spec: TrialSpec) -> Optimizer:
    """Returns the fresh optimizer a spec describes (raises ValueError for bad options)."""
    from linkevo.algorithms import make_optimizer

    return make_optimizer(
        spec.approach,
        fitness=spec.fitness,
        batch_size=spec.batch_size,
        mode=spec.mode,
        seed=spec.seed,
        n_angles=spec.n_angles,
        **spec.options,
    )


def check_spec_options(spec: TrialSpec) -> None:
    """Raises ValueError, naming the option, for options its approach would refuse, without
    building the optimizer where that is costly (MAP-AU's autoencoder needs torch)."""
    from linkevo.algorithms.factory import check_options

    check_options(spec.approach, spec.options)
