"""Provides the checks a grid's launch makes before it writes anything, light enough for
`linkevo grid --dry-run` to make them too (no Ray, MLflow or torch is imported): every
trial's spec and options, the store, a resume's and a restart's consistency."""

from __future__ import annotations

import json
import urllib.error
import urllib.request
from pathlib import Path
from typing import TYPE_CHECKING

from linkevo.orchestrator.config import ConfigError
from linkevo.orchestrator.grid import Grid
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.tracking import check_store_file

if TYPE_CHECKING:
    from linkevo.workers.store.runs import RunStore
    from linkevo.workers.trial_spec import TrialSpec


def check_tracking_uri(uri: str, timeout: float = 5.0) -> None:
    """Raises ConfigError when an HTTP tracking server does not answer its health check."""
    if not uri.startswith(("http://", "https://")):
        return
    url = uri.rstrip("/") + "/health"
    try:
        with urllib.request.urlopen(url, timeout=timeout) as response:
            if response.status == 200:
                return
            problem = f"HTTP {response.status}"
    except (urllib.error.URLError, OSError) as exc:
        problem = str(getattr(exc, "reason", exc))
    raise ConfigError(
        f"tracking URI {uri!r} is unreachable ({url}: {problem}); start the server, or "
        "allowed: an http(s):// MLflow server that answers /health, a sqlite:/// URI, "
        "or a folder for an embedded store"
    )


def check_store(uri: str) -> None:
    """Refuses a store the grid cannot write, before anything is written: a tracking
    server that does not answer, an embedded store file that is damaged."""
    check_tracking_uri(uri)
    check_store_file(uri)


def check_store_holds_grid(record: Path, uri: str, grid: Grid) -> None:
    """Refuses `--resume` on a store that holds no run of the grid when the grid's own
    record (`grid.grid_record`) says it ran: the store was emptied or replaced, and a
    resume would run every trial again beside the old files.

    Raises:
        ConfigError: naming both stores, the record and the choices.
    """
    try:
        ran = json.loads(record.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return  # never launched here (or an unreadable record): nothing to protect
    raise ConfigError(
        f"--resume: the store {uri} holds no run of grid {grid.grid_id}, but {record} says "
        f"it ran in {ran.get('tracking_uri')!r} as parent run {ran.get('parent_run_id')!r}: "
        "the store was emptied or replaced. Resume against the store it ran in "
        f"(--tracking-uri), or move {record.parent} away and launch the grid afresh "
        "(same config, no --resume): its seeds make it the same grid"
    )


def trial_specs(grid: Grid) -> dict[str, TrialSpec]:
    """Returns every trial's spec by key, checking each approach's options by building
    its optimizer once; raises ConfigError before any trial starts."""
    from linkevo.sim.study import WALKING_FITNESS
    from linkevo.workers.trial_spec import TrialSpec, check_spec_options

    cfg = grid.config
    specs: dict[str, TrialSpec] = {}
    for cell in grid.cells:
        settings = dict(
            mode=cfg.mode,
            seed=cell.seed,
            target=cfg.target,
            n_angles=cfg.n_angles,
            checkpoint_every=cfg.checkpoint_every,
            max_seconds=cfg.max_seconds,
            options=dict(cfg.options.get(cell.approach, {})),
            physics=dict(cfg.physics),
            gait=dict(cfg.gait),
            mounting=dict(cfg.mounting),
        )
        try:
            if cell.fitness == WALKING_FITNESS:
                spec = TrialSpec.walking(
                    cell.approach,
                    cfg.walks,
                    batch_size=cfg.walk_batch,
                    seed_from=cfg.seed_from,
                    surrogate=cfg.surrogate,
                    walk_model=cfg.walk_model,
                    **settings,
                )
            else:
                spec = TrialSpec(
                    cell.approach,
                    cell.fitness,
                    cfg.evaluations,
                    batch_size=cfg.batch_size,
                    walk_rerank=cfg.walk_rerank,
                    **settings,
                )
            if cell.index == 0:
                check_spec_options(spec)
        except ValueError as exc:
            raise ConfigError(f"trial {cell.key}: {exc}") from exc
        specs[cell.key] = spec
    return specs


def check_walk_model(store: RunStore, run_id: str) -> None:
    """Raises ConfigError unless `run_id` (grid key `walk_model`; "" passes) is a walk model
    of the store that this linkevo's features fit: what a SAIL trial's head start reads."""
    if not run_id:
        return
    from linkevo.workers.store.runs import NotFound
    from linkevo.workers.store.walk_models import WalkModelError, load_model

    try:
        load_model(store, run_id)
    except (NotFound, WalkModelError) as exc:
        raise ConfigError(f"config key 'walk_model' = {run_id!r} is invalid: {exc}") from None


def check_seed(store: RunStore, run_id: str) -> None:
    """Raises ConfigError unless `run_id` (grid key `seed_from`; "" passes) is a MAP-Elites
    trial of the store with a repertoire and a walk map: what a warm start reads."""
    if not run_id:
        return
    from linkevo.sim.study import is_map_elites
    from linkevo.workers.store.runs import NotFound

    try:
        approach = store.tags(run_id).get(layout.APPROACH, "")
    except NotFound:
        raise ConfigError(
            f"config key 'seed_from' = {run_id!r} is invalid: no such run in {store.uri}"
        ) from None
    held = store.artefact_names(run_id)
    missing = [n for n in (layout.REPERTOIRE, layout.WALK_MAP) if n not in held]
    if not is_map_elites(approach) or missing:
        raise ConfigError(
            f"config key 'seed_from' = {run_id!r} is invalid: a warm start needs a MAP-Elites "
            f"trial with a walk map; this run is {approach or 'not a trial'}"
            + (f" without {', '.join(missing)}" if missing else "")
            + (f" (`linkevo walkmap {run_id}` makes its walk map)" if missing else "")
        )
    import tempfile

    with tempfile.TemporaryDirectory(prefix="linkevo-seed-") as tmp:  # both read and checked
        store.repertoire(run_id, Path(tmp) / "repertoire")
        store.walk_map(run_id, Path(tmp) / "walks")


def check_no_shrink(grid: Grid, earlier: list) -> None:
    """Raises ConfigError when the store holds trials of the grid beyond its `trials`
    (a grid's trial count may grow on `--resume`, never shrink: the report would hide the
    trials left out)."""
    indices = [int(r.data.tags.get(layout.TRIAL_INDEX, -1)) for r in earlier]
    held = max(indices, default=-1) + 1
    if held > grid.config.trials:
        raise ConfigError(
            f"config key 'trials' = {grid.config.trials} is invalid for grid {grid.grid_id}: "
            f"its store already holds trials up to index {held - 1}; allowed: >= {held}"
        )


def check_restart(grid: Grid, restart: tuple[str, ...], resume: bool) -> None:
    """Raises ConfigError for a `--restart-trial` key the grid lacks, or without resume."""
    if not restart:
        return
    if not resume:
        raise ConfigError("--restart-trial needs --resume: it restarts a trial of a grid")
    keys = {cell.key for cell in grid.cells}
    for key in restart:
        if key not in keys:
            raise ConfigError(
                f"--restart-trial {key!r}: not a trial of grid {grid.grid_id}; allowed: a "
                f"trial key APPROACH/FITNESS/INDEX such as {grid.cells[0].key}"
            )
