"""The MLflow run layout: how linkevo's runs are tagged, named and found.

A grid is a parent run (kind "grid"); each trial is a nested run (kind "trial") tagged with
its grid id and trial key; a field trial, real or simulated, is a run of kind
"field_trial"; a learned walk model is a run of kind "walk_model". Every module that writes
or reads runs takes the names from here; searches go through
`workers.store.runs.RunStore`, which pages through all results and puts values in a filter
only through `where` and `quote` (`docs/grid.md` shows the layout).
"""

from __future__ import annotations

import re

KIND = "linkevo.kind"
"""The tag every linkevo run carries: one of the kinds below."""
GRID, TRIAL, FIELD_TRIAL = "grid", "trial", "field_trial"
WALK_MODEL = "walk_model"
"""A learned walk model's run (`linkevo walkmodel fit`): its weights, features and figures."""
FEATURES = "features"
"""A walk model's tag: the version of the features it was fitted on
(`sim.robot.walk_features.FEATURES_VERSION`); a model of other features is refused."""
PARENT = "mlflow.parentRunId"
NOTE = "mlflow.note.content"
GRID_ID = "grid_id"
TRIAL_KEY = "trial_key"
TRIAL_INDEX = "trial_index"
APPROACH = "approach"
FITNESS = "fitness"
SEED = "seed"
CODE_VERSION = "code_version"
TRIALS = "trials"
"""A grid parent's trials per approach and fitness: the latest launch's (a grid extended
with `--resume --set trials=N` holds more than its first launch)."""
HOST = "host"
RAY_NODE = "ray_node"
TRIAL_TAGS: tuple[str, str, str] = (APPROACH, FITNESS, TRIAL_INDEX)
"""The tags that place a trial in the study's order."""
ERROR = "error"
"""A failed run's message (its first `ERROR_CHARS` characters)."""
ERROR_CHARS = 500
STOPPED_BY = "stopped_by"
"""How a trial ended: "budget", or "max_seconds" when its time limit cut it short."""

# A field trial's run (kind "field_trial"): the linkage it walked, where and how.
SOURCE_RUN_ID = "source_run_id"
"""A field trial's tag: the run its linkage came from ("" for a linkage document)."""
SOURCE_CELL = "source_cell"
"""A field trial's tag: the repertoire cell its linkage came from, or "best"."""
SOURCE_GRID = "source_grid_id"
"""A field trial's tag: the grid of the trial its linkage came from."""
LINKAGE = "linkage"
"""A field trial's tag: `hardware.field_trial.linkage_key` of the linkage it walked."""
ROBOT = "robot"
"""A field trial's tag: which of Table I's robots (`sim.study.ROBOTS`)."""
FLOOR = "floor"
"""A field trial's tag: the floor it walked on."""
BREAKS = "breaks"
"""A simulated field trial's tag: "True" when the simulated robot breaks."""
REASON = "reason"
"""A simulated field trial's tag: why it breaks."""
SIMULATED = "simulated"
"""A field trial's param: where it walked, one of `REAL`, `EMULATOR`, `PHYSICS`."""
REAL, EMULATOR, PHYSICS = "False", "True", "physics"
"""The values of `SIMULATED`: on the robot, on the bus emulator (the driver's dry run;
distances typed in), in the 3-D simulation (`linkevo hexapod simulate`; predicted)."""
SECONDS = "seconds"
"""A field trial's param: each walk's length."""
DISTANCE_CM = "distance_cm"
"""A field trial's metric: the distance of each repeat (step = repeat)."""
MEAN_DISTANCE_CM = "mean_distance_cm"
"""A field trial's metric: the mean over its repeats."""

LEASE_PREFIX = "linkevo.lease."
"""An experiment tag `linkevo.lease.<grid_id>` (the driver running that grid) or
`linkevo.lease.walkmap.<run_id>` (the process making that run's walk map)
(`orchestrator.lease`)."""

GRID_CONFIG_JSON = "grid_config.json"
GRID_CONFIG_TOML = "grid_config.toml"
GRID_SUMMARY = "grid_summary.json"
"""A grid parent's table of its cells (MLflow's table JSON: `columns` and `data`)."""
BEST_JSON = "best_linkage.json"
"""A trial's best linkage, as `sim.linkage.linkage_doc` writes it."""
BEST_PNG = "best_linkage.png"
LINKAGE_JSON = "linkage.json"
"""A linkage document where it is not a trial's best: a field trial's, the one `pull` writes."""
EXPLORER_HTML = "explorer.html"
"""The explorer page among a run's artefacts (a trial's run, or a grid's parent run)."""
METRICS_FILE = "metrics.csv"
"""A trial's metrics, a row per iteration (`workers.recorders.MetricsCsv`)."""
SETTINGS_FILE = "settings.json"
RESULT_FILE = "result.json"
ENCODER_PT = "encoder.pt"
"""MAP-AU's encoder as a torch state dict (`torch.load(path, weights_only=True)`)."""
CHECKPOINT_DIR = "checkpoint"
"""A trial folder's checkpoint folder (`workers.checkpoint`); local, never logged."""
REPERTOIRE = "repertoire.parquet"
POPULATION = "population.parquet"
WALK_MAP = "walkmap.parquet"
"""A repertoire trial's walk map: a row per walked cell and floor (`sim.robot.walk_rows.COLUMNS`
plus the cell's bins), logged by `linkevo walkmap`, or by a walking trial (fitness F_w)
itself."""
WALK_MAP_PNG = "walkmap.png"
WALK_MAP_ROBOT = "walk_map_robot"
"""The tag of a run with a walk map: what the walked robot changes from the study's, by part
(physics, gait, phases; `sim.robot.hexapod.Robot.changed`), as JSON; "{}" for the study's
robot."""
WALK_MAP_PHYSICS = "walk_map_physics"
"""An older linkevo's tag of a walk map's robot: its physics alone (read, never written)."""
WALK_PREDICTION = "walkpred.parquet"
"""A repertoire trial's predicted walks (`linkevo walkmodel predict`): a row per filled cell
and floor (`workers.store.tables.PREDICTION_COLUMNS` plus the cell's bins); the run's tag
`PREDICTED_BY` names the model's run."""
PREDICTION_MAP = "prediction_map.parquet"
"""A SAIL trial's prediction map (`workers.walk_sail`): a row per cell its walk model
illuminated, as a repertoire's (cell, loss, error, desc_d, bin_d, genome) with the
predicted walk per floor (`<floor>_predicted_cm`, `<floor>_spread_cm`, `<floor>_p_break`)
and whether the cell is in the walked map (`walked`)."""
PREDICTED_BY = "walk_model"
"""The tag of a trial run whose walks were predicted: the walk model's run id."""
WALK_MODEL_PT = "walk_model.pt"
"""A walk model's weights as a torch state dict (`torch.load(path, weights_only=True)`)."""
WALK_MODEL_JSON = "walk_model.json"
"""A walk model's description: its features, the repertoires it learned from and was
measured on, its held-out figures."""
WALK_MODEL_PNG = "walk_model.png"
WALK_LOG = "walks.parquet"
"""A walking trial's walk log: a row per candidate it built (its stage, leg key, node,
seconds and each floor's figures; `workers.walk_log.WalkLog`)."""
BEST_CONFIRMED = "best_confirmed.json"
"""A walking trial's best walker walked again on the full model from hand-placed starts
(`sim.robot.confirmation`): each floor's lean and full distances, whether they agree, and
whether the full model's repeats disagree widely."""
WALK_RERANK = "walk_rerank.parquet"
"""A trial's re-ranking walks (grid key `walk_rerank`): its K best linkages walked."""
BEST_WALKER = "best_walker.json"
"""Of those, the furthest walker that does not break, as `sim.linkage.linkage_doc` writes it."""

ID_PATTERN = re.compile(r"[A-Za-z0-9_-][A-Za-z0-9_.-]{0,63}")
"""What a run id or grid id may hold, typed or read back from a store (a grid id is 12 hex
digits): no path separator, no leading dot, so an id can name a folder."""
_KEY = re.compile(r"(?P<approach>[A-Za-z0-9_-]+)/(?P<fitness>[A-Za-z0-9_]+)/(?P<index>\d{2,})")
_SAFE = re.compile(r"[A-Za-z0-9_./:+-]*")


def trial_key(approach: str, fitness: str, index: int) -> str:
    """Returns the trial key, e.g. "MAP-LIS/Fp/03": unique in a grid, stable across runs."""
    return f"{approach}/{fitness}/{index:02d}"


def error_text(exc: BaseException) -> str:
    """Returns the `error` tag of a run that `exc` ended: its type and message, first
    `ERROR_CHARS` characters, with a database error's SQL statement and parameters left
    out (SQLAlchemy appends them after the message; they say nothing to a user and can
    be long)."""
    message = str(exc).split("\n[SQL:", 1)[0].split("\n(Background on this error", 1)[0]
    return f"{type(exc).__name__}: {message.strip()}"[:ERROR_CHARS]


def lease_tag(name: str) -> str:
    """Returns the experiment tag that holds a lease: a grid id, or `walkmap.<run_id>`."""
    return f"{LEASE_PREFIX}{checked_id(name, 'lease')}"


def parse_trial_key(key: str) -> tuple[str, str, int]:
    """Returns (approach, fitness, index) of a trial key.

    Raises:
        ValueError: naming the key and the allowed form.
    """
    found = _KEY.fullmatch(key)
    if found is None:
        raise ValueError(f"trial key {key!r}: allowed APPROACH/FITNESS/NN, e.g. MAP-LIS/Fp/03")
    return found["approach"], found["fitness"], int(found["index"])


def checked_id(value: str, what: str) -> str:
    """Returns `value` if it is a well-formed id (`ID_PATTERN`).

    Ids read back from a store (a shared one, say) are checked before they name a folder
    or go into a search.

    Raises:
        ValueError: naming `what` (where the value came from), the value and what is allowed.
    """
    if not ID_PATTERN.fullmatch(value):
        raise ValueError(
            f"{what} {value!r} is not an id; allowed: up to 64 letters, digits, '_', '-' "
            "and '.', not starting with '.'"
        )
    return value


def quote(value: str) -> str:
    """Returns `value` as a quoted literal for an MLflow filter string.

    MLflow's filter grammar has no escape for a quote inside a literal, so a value holding
    anything beyond letters, digits and `_ . / : + -` is refused: a tag read back from a
    shared store cannot change what a search means.

    Raises:
        ValueError: naming the value and the allowed characters.
    """
    if not _SAFE.fullmatch(value):
        raise ValueError(
            f"{value!r} cannot be searched for: allowed letters, digits and _ . / : + -"
        )
    return f"'{value}'"


def where(kind: str | None = None, status: str | None = None, **tags: str) -> str:
    """Returns a filter string: the run kind, a run status and tags equal to values."""
    clauses = [f"tags.`{KIND}` = {quote(kind)}"] if kind else []
    clauses += [f"tags.`{name}` = {quote(value)}" for name, value in tags.items()]
    if status:
        clauses.append(f"attributes.status = {quote(status)}")
    return " and ".join(clauses)
