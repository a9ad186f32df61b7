"""The study's vocabulary: its approaches and fitnesses (names, labels, order, flags) and its
defaults.

Every layer that names an approach or a fitness reads it from here, so each has one
spelling: the `name` is what configs, the command line, MLflow tags and tables use; the
`label` is how a figure captions it (the paper's spelling). Tuples are in the study's
order, which reports and tables follow.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Approach:
    """One search approach.

    Attributes:
        name: the spelling in configs, tags and tables ("NSGA2").
        label: the spelling in figures ("NSGA-II").
        family: "population" (EA, NSGA-II), "map-elites" or "baseline" (random sampling).
        multi_objective: optimises the two-objective variant of its fitness.
        learned_grid: its grid's dimensions are learned anew in each trial (AURORA), so
            two trials' cells are not the same cells.
    """

    name: str
    label: str
    family: str
    multi_objective: bool = False
    learned_grid: bool = False

    @property
    def repertoire(self) -> bool:
        """Keeps a repertoire (an archive on a grid) rather than a population."""
        return self.family != "population"


@dataclass(frozen=True)
class Fitness:
    """One fitness function a trial optimises.

    Attributes:
        name: the spelling in configs, tags and tables ("Fp").
        label: the spelling in figures ("F_p").
        two_objective: the variant a multi-objective approach evaluates ("Fp2").
        walks: the loss comes from walking the robot (`sim.robot.walk_fitness`), not from the
            2-D kernel; its budget is walked candidates.
    """

    name: str
    label: str
    two_objective: str
    walks: bool = False


APPROACH_TABLE: tuple[Approach, ...] = (
    Approach("EA", "EA", "population"),
    Approach("NSGA2", "NSGA-II", "population", multi_objective=True),
    Approach("MAP-WH", "MAP-WH", "map-elites"),
    Approach("MAP-LIS", "MAP-LIS", "map-elites"),
    Approach("MAP-ST", "MAP-ST", "map-elites"),
    Approach("MAP-AU", "MAP-AU", "map-elites", learned_grid=True),
    Approach("RANDOM", "RANDOM", "baseline"),
)
FITNESS_TABLE: tuple[Fitness, ...] = (
    Fitness("Fp", "F_p", "Fp2"),
    Fitness("Fsl", "F_sl", "Fsl2"),
    Fitness("Fw", "F_w", "Fw2", walks=True),
)

APPROACH: dict[str, Approach] = {a.name: a for a in APPROACH_TABLE}
APPROACHES: tuple[str, ...] = tuple(APPROACH)
"""Every approach: the study's six and the RANDOM baseline."""
MAP_ELITES: tuple[str, ...] = tuple(a.name for a in APPROACH_TABLE if a.family == "map-elites")
"""The MAP-Elites approaches of the study (each with its own descriptor grid)."""
STUDY_APPROACHES: tuple[str, ...] = tuple(a.name for a in APPROACH_TABLE if a.family != "baseline")
"""The study's six approaches."""
BASELINE = "RANDOM"
"""The random-sampling baseline, compared with each approach beside the study's own pairs."""
REPERTOIRE_APPROACHES: tuple[str, ...] = tuple(a.name for a in APPROACH_TABLE if a.repertoire)
"""Approaches that keep a repertoire rather than a population."""
LEARNED: tuple[str, ...] = tuple(a.name for a in APPROACH_TABLE if a.learned_grid)
"""Approaches whose grid is learned per trial: their trials' cells do not pool."""
MULTI_OBJECTIVE: tuple[str, ...] = tuple(a.name for a in APPROACH_TABLE if a.multi_objective)
"""Approaches that optimise the two-objective variant of their fitness."""

FITNESS: dict[str, Fitness] = {f.name: f for f in FITNESS_TABLE}
SINGLE_FITNESSES: tuple[str, ...] = tuple(FITNESS)
"""The fitness functions a trial optimises ("Fp", "Fsl", "Fw")."""
FITNESSES: tuple[str, ...] = (*SINGLE_FITNESSES, *(f.two_objective for f in FITNESS_TABLE))
"""Every fitness and its two-objective variant, in the study's order."""
PATH_FITNESSES: tuple[str, ...] = (
    *(f.name for f in FITNESS_TABLE if not f.walks),
    *(f.two_objective for f in FITNESS_TABLE if not f.walks),
)
"""The fitnesses of the foot path that `sim.linkage.evaluating` computes ("Fp", "Fsl", "Fp2",
"Fsl2")."""
WALKING_FITNESS = "Fw"
"""The walking fitness: a trial's loss from its candidates walked on the robot."""
STUDY_FITNESSES: tuple[str, ...] = tuple(f.name for f in FITNESS_TABLE if not f.walks)
"""The study's two fitness functions (the paper's F_p and F_sl)."""
MODES: tuple[str, ...] = ("paper", "legacy")
"""The simulation's modes (spec: paper by default, legacy as the published code)."""
TARGETS: tuple[str, ...] = ("D16", "D24")
"""The published target paths a fitness can be measured against (or a file)."""

STUDY_EVALUATIONS = 726_750
"""Evaluations per trial in the study (one hour on 16 CPUs, spec §6); whole batches of
5,000 make it 725,000."""
DEFAULT_BATCH = 5000
"""Genomes asked for and evaluated per iteration (the study's batch)."""
DEFAULT_ANGLES = 40
"""Crank angles simulated per turn (the study's 40)."""
MIN_ANGLES = 3
"""The fewest crank angles a trial accepts: a path needs three points to have a shape."""
DEFAULT_WALK_BATCH = 32
"""Candidates per iteration of a walking trial: enough to keep a few evaluator actors busy
(2-D rejections and repeated legs cost no walk), few enough that a budget of walks is met
closely."""
MAX_WALKS = 10_000_000
"""The most walks a walking trial may be given (about 16 months of one core)."""
CANDIDATES_PER_WALK = 100
"""A walking trial's guard: it ends after this many candidates per walk in its budget,
should its search stop proposing legs that can be walked."""
SURROGATES: tuple[str, ...] = ("", "screen", "sail")
"""How a walking MAP-Elites trial uses the learned walk model: not at all, to screen what
its search proposes, or to run the search itself (SAIL)."""
SAIL_APPROACHES: tuple[str, ...] = ("MAP-WH", "MAP-LIS", "MAP-ST")
"""The MAP-Elites approaches a SAIL trial runs: fixed descriptors (MAP-AU's are learned
from the archive it fills, which a model of walks cannot predict)."""


ROBOTS: tuple[str, ...] = ("first", "modified")
"""Table I's robots of an approach: the first, built from a region of its map, and the
modified one, from a neighbouring region."""


def label(name: str) -> str:
    """Returns the figure label of an approach or fitness name ("NSGA2" -> "NSGA-II")."""
    item = APPROACH.get(name) or FITNESS.get(name)
    return item.label if item else name


def is_map_elites(approach: str) -> bool:
    """Returns True for the MAP-Elites approaches."""
    return approach in MAP_ELITES


def walks(fitness: str) -> bool:
    """Returns True for a fitness whose loss comes from walking (F_w and F_w2)."""
    return fitness in (WALKING_FITNESS, FITNESS[WALKING_FITNESS].two_objective)


def is_pareto(approach: str) -> bool:
    """Returns True for the multi-objective approach (NSGA-II)."""
    return approach in MULTI_OBJECTIVE


def evaluated_fitness(fitness: str, multi_objective: bool) -> str:
    """Returns the `sim.linkage.evaluating` fitness behind `fitness`: its two-objective variant for
    a multi-objective approach, else itself."""
    return FITNESS[fitness].two_objective if multi_objective else fitness


def ordered(names, order: tuple[str, ...]) -> list[str]:
    """Returns `names` in the study's `order`, unknown names last in sorted order."""
    names = set(names)
    return [n for n in order if n in names] + sorted(n for n in names - set(order))
