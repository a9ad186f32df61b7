"""Provides `RunStore`: every call linkevo makes to an MLflow store, in one typed API.

A command opens the store once (`RunStore.open`) and asks it for a grid's parent run, its
trial runs (as runs, or as one table), the repertoire trials a reference names, a run's
artefacts read back and checked (`workers.store.tables`); and writes through it: runs
created and ended, their tags, params, metrics and artefacts, the experiment's tags (the
leases). The searches page through all results and quote every value they put in a filter
(`run_layout.where`). No other module holds an MLflow client. Optuna's storages, one
object behind every study's reads and writes, are the model.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from linkevo.sim.errors import LinkevoError
from linkevo.sim.study import DEFAULT_ANGLES, REPERTOIRE_APPROACHES
from linkevo.workers.store import run_layout as layout

if TYPE_CHECKING:
    import pandas as pd
    from mlflow.entities import Run
    from mlflow.tracking import MlflowClient

PAGE = 1000
"""Runs per search page (MLflow's SQL stores accept up to 50,000)."""


class NotFound(LinkevoError, LookupError):
    """A grid, run or artefact the store does not hold; the message says what it holds."""


@dataclass(frozen=True)
class TrialRun:
    """One repertoire trial: its run, tags and settings."""

    run_id: str
    trial_key: str
    approach: str
    fitness: str
    mode: str
    n_angles: int


@dataclass(frozen=True)
class Repertoires:
    """The repertoire trials a reference names: one trial's (grid_id and parent_run_id
    None), or every finished repertoire trial of a grid."""

    trials: list[TrialRun]
    grid_id: str | None = None
    parent_run_id: str | None = None


class RunStore:
    """One MLflow store and linkevo's experiment in it.

    Args:
        uri: an absolute tracking URI (`tracking.resolve_tracking_uri`).
        experiment: the experiment's name.
        experiment_id: its id, where the caller knows it (a Ray task of a grid).
    """

    def __init__(
        self, uri: str, experiment: str = "linkevo", *, experiment_id: str | None = None
    ) -> None:
        from mlflow.tracking import MlflowClient

        self.uri = uri
        self.experiment = experiment
        self._client: MlflowClient = MlflowClient(tracking_uri=uri)
        self._experiment_id = experiment_id

    @classmethod
    def of_experiment(cls, uri: str, experiment_id: str) -> RunStore:
        """Returns the store at an absolute `uri` in the experiment with that id (created
        in an older store as `tracking.ensure_experiment` would, with its tags).

        Raises:
            NotFound: the store has no experiment of that id.
        """
        from mlflow.exceptions import MlflowException

        from linkevo.workers.store.tracking import ensure_experiment

        try:
            name = cls(uri, experiment_id=experiment_id)._client.get_experiment(experiment_id).name
        except MlflowException as exc:
            raise NotFound(f"no MLflow experiment {experiment_id!r} in the store {uri}") from exc
        return cls(uri, name, experiment_id=ensure_experiment(uri, name))

    @classmethod
    def open(cls, uri: str | None = None, experiment: str = "linkevo") -> RunStore:
        """Returns the store at `uri` (default: MLFLOW_TRACKING_URI, else the embedded
        one), which must exist: reading never creates a store.

        Raises:
            TrackingUriError: an unsupported URI, or no store (or a damaged one) there.
        """
        from linkevo.workers.store.tracking import require_store, resolve_tracking_uri

        return cls(require_store(resolve_tracking_uri(uri)), experiment)

    @property
    def experiment_id(self) -> str:
        """The experiment's id.

        Raises:
            NotFound: the store has no such experiment.
        """
        if self._experiment_id is None:
            found = self._client.get_experiment_by_name(self.experiment)
            if found is None:
                raise NotFound(f"no MLflow experiment {self.experiment!r} in the store {self.uri}")
            self._experiment_id = found.experiment_id
        return self._experiment_id

    @property
    def has_experiment(self) -> bool:
        """Whether the store holds the experiment."""
        return self._client.get_experiment_by_name(self.experiment) is not None

    def experiment_tag(self, name: str) -> str | None:
        """Returns the experiment's tag `name`, or None."""
        return self._client.get_experiment(self.experiment_id).tags.get(name)

    def set_experiment_tag(self, name: str, value: str) -> None:
        """Sets the experiment's tag `name`."""
        self._client.set_experiment_tag(self.experiment_id, name, value)

    def delete_experiment_tag(self, name: str) -> None:
        """Deletes the experiment's tag `name`."""
        self._client.delete_experiment_tag(self.experiment_id, name)

    def run(self, run_id: str) -> Run:
        """Returns a run.

        Raises:
            NotFound: the store has no such run.
        """
        from mlflow.exceptions import MlflowException

        try:
            return self._client.get_run(run_id)
        except MlflowException as exc:
            raise NotFound(f"no run {run_id!r} in the store {self.uri}") from exc

    def tags(self, run_id: str) -> dict[str, str]:
        """Returns a run's tags (NotFound as `run`)."""
        return dict(self.run(run_id).data.tags)

    def params(self, run_id: str) -> dict[str, str]:
        """Returns a run's params (NotFound as `run`)."""
        return dict(self.run(run_id).data.params)

    def status(self, run_id: str) -> str:
        """Returns a run's status: RUNNING, FINISHED, FAILED or KILLED (NotFound as `run`)."""
        return self.run(run_id).info.status

    def metric_history(self, run_id: str, name: str) -> dict[int, float]:
        """Returns a run's values of metric `name` by step, in step order (a step logged
        twice: its latest value)."""
        history = self._client.get_metric_history(run_id, name)
        return {m.step: m.value for m in sorted(history, key=lambda m: (m.step, m.timestamp))}

    def artefact_names(self, run_id: str) -> set[str]:
        """Returns the names of a run's top-level artefacts (files and folders)."""
        return {a.path for a in self._client.list_artifacts(run_id)}

    def create_run(
        self, run_name: str, tags: dict[str, str], *, experiment_id: str | None = None
    ) -> str:
        """Creates a RUNNING run in the experiment (or `experiment_id`) and returns its id."""
        experiment = experiment_id or self.experiment_id
        return self._client.create_run(experiment, run_name=run_name, tags=tags).info.run_id

    def set_running(self, run_id: str) -> None:
        """Marks a run RUNNING again (a grid resumed)."""
        self._client.update_run(run_id, status="RUNNING")

    def end_run(self, run_id: str, status: str = "FINISHED", message: str = "") -> None:
        """Ends a run with `status`; a message (why it failed or was killed) goes into its
        `error` tag, cut to `run_layout.ERROR_CHARS`."""
        if message:
            self._client.set_tag(run_id, layout.ERROR, message[: layout.ERROR_CHARS])
        self._client.set_terminated(run_id, status)

    def set_tag(self, run_id: str, name: str, value: str) -> None:
        """Sets a run's tag."""
        self._client.set_tag(run_id, name, value)

    def delete_tag(self, run_id: str, name: str) -> None:
        """Deletes a run's tag."""
        self._client.delete_tag(run_id, name)

    def log_params(self, run_id: str, params: dict[str, object]) -> None:
        """Logs a run's params (as text), a hundred per call (MLflow's limit)."""
        from mlflow.entities import Param

        items = [Param(k, str(v)) for k, v in params.items()]
        for start in range(0, len(items), 100):
            self._client.log_batch(run_id, params=items[start : start + 100])

    def log_metric(self, run_id: str, name: str, value: float, step: int = 0) -> None:
        """Logs one value of a run's metric."""
        self._client.log_metric(run_id, name, value, step=step)

    def log_artefact(self, run_id: str, path: Path, folder: str | None = None) -> None:
        """Logs a local file (or folder) as a run's artefact, under `folder` when given."""
        self._client.log_artifact(run_id, str(path), folder)

    def log_document(self, run_id: str, document: dict, name: str) -> None:
        """Logs a JSON document as a run's artefact `name`."""
        self._client.log_dict(run_id, document, name)

    def log_text(self, run_id: str, text: str, name: str) -> None:
        """Logs a text as a run's artefact `name`."""
        self._client.log_text(run_id, text, name)

    def recorder(self, run_id: str, outage_s: float):
        """Returns a trial recorder logging to the run (`MlflowRecorder`)."""
        from linkevo.workers.store.mlflow_recorder import MlflowRecorder

        return MlflowRecorder(self._client, run_id, outage_s=outage_s)

    def search(
        self, filter_string: str, *, order_by: list[str] | None = None, limit: int | None = None
    ) -> list[Run]:
        """Returns every run of the experiment matching `filter_string` (or the first
        `limit`), page by page."""
        runs: list[Run] = []
        token = None
        ids = [self.experiment_id]
        while limit is None or len(runs) < limit:
            size = PAGE if limit is None else min(PAGE, limit - len(runs))
            page = self._client.search_runs(
                ids, filter_string, order_by=order_by, max_results=size, page_token=token
            )
            runs.extend(page)
            token = page.token
            if not token:
                break
        return runs

    def trial_runs(
        self, grid_id: str, *, trial_key: str | None = None, status: str | None = None
    ) -> list[Run]:
        """Returns the grid's trial runs, optionally of one trial key and/or one status."""
        tags = {layout.GRID_ID: grid_id} | ({layout.TRIAL_KEY: trial_key} if trial_key else {})
        return self.search(layout.where(layout.TRIAL, status, **tags))

    def grid_runs(
        self, grid_id: str | None = None, *, first: bool = False, limit: int | None = None
    ) -> list[Run]:
        """Returns the grid runs (of one grid id when given), the latest started first
        (`first`: the earliest first)."""
        tags = {layout.GRID_ID: grid_id} if grid_id is not None else {}
        order = "ASC" if first else "DESC"
        return self.search(
            layout.where(layout.GRID, **tags),
            order_by=[f"attributes.start_time {order}"],
            limit=limit,
        )

    def grid(self, grid_id: str | None = None) -> tuple[str, str]:
        """Returns (grid_id, parent_run_id) of `grid_id`, or of the latest grid when None.

        Raises:
            NotFound: no such experiment or grid; the message lists the known grids.
        """
        wellformed = grid_id is None or layout.ID_PATTERN.fullmatch(grid_id)
        runs = self.grid_runs(grid_id, limit=1) if wellformed else []
        if not runs:
            known = sorted({r.data.tags.get(layout.GRID_ID, "?") for r in self.grid_runs(limit=20)})
            wanted = "any grid" if grid_id is None else f"grid {grid_id!r}"
            raise NotFound(
                f"no {wanted} in experiment {self.experiment!r}; known grids: "
                f"{', '.join(known) or 'none'}"
            )
        run = runs[0]
        try:
            found = layout.checked_id(
                run.data.tags[layout.GRID_ID], f"the grid_id tag of run {run.info.run_id}"
            )
        except ValueError as exc:
            raise NotFound(f"{exc}; pass a grid id that is one") from exc
        return found, run.info.run_id

    def trial_table(self, grid_id: str) -> pd.DataFrame:
        """Returns the grid's trial runs as a table, one row per run: run_id, status,
        artifact_uri, start_time, `tags.<name>` and `metrics.<name>` (last values)."""
        import pandas as pd

        records = []
        for run in self.trial_runs(grid_id):
            record = {
                "run_id": run.info.run_id,
                "status": run.info.status,
                "artifact_uri": run.info.artifact_uri,
                "start_time": run.info.start_time,
            }
            record.update({f"tags.{k}": v for k, v in run.data.tags.items()})
            record.update({f"metrics.{k}": v for k, v in run.data.metrics.items()})
            records.append(record)
        return pd.DataFrame.from_records(records)

    def repertoire_trial(self, run_id: str) -> TrialRun:
        """Returns a repertoire trial's identity from its run.

        Raises:
            NotFound: no such run, or a run whose approach keeps no repertoire.
        """

        try:
            run = self.run(run_id)
        except NotFound as exc:
            raise NotFound(f"{run_id!r} is neither a trial run nor a grid id here") from exc
        tags, params = run.data.tags, run.data.params
        approach = tags.get(layout.APPROACH, "unknown")
        if approach not in REPERTOIRE_APPROACHES:
            raise NotFound(
                f"run {run_id} is a {approach} trial, which keeps a population, not a "
                f"repertoire; give a trial of {', '.join(REPERTOIRE_APPROACHES)} or a grid id"
            )
        return TrialRun(
            run_id=run_id,
            trial_key=tags.get(layout.TRIAL_KEY, run_id),
            approach=approach,
            fitness=tags.get(layout.FITNESS, "unknown"),
            mode=params.get("mode", "paper"),
            n_angles=int(params.get("n_angles", DEFAULT_ANGLES)),
        )

    def grid_repertoires(self, grid_id: str) -> list[TrialRun]:
        """Returns a grid's FINISHED repertoire trials in the study's order (one run per
        trial key).

        Raises:
            NotFound: the grid has none.
        """
        approach, fitness, index = (f"tags.{t}" for t in layout.TRIAL_TAGS)
        runs = self.trial_table(grid_id)
        if runs.empty or approach not in runs:
            raise NotFound(f"grid {grid_id} has no trial runs")
        runs = latest_per_trial(runs)
        runs = runs[(runs.status == "FINISHED") & runs[approach].isin(REPERTOIRE_APPROACHES)]
        if runs.empty:
            raise NotFound(
                f"grid {grid_id} has no finished trial of {', '.join(REPERTOIRE_APPROACHES)}"
            )
        runs = in_study_order(runs, approach, fitness, index if index in runs else None)
        return [self.repertoire_trial(run_id) for run_id in runs.run_id]

    def repertoires(self, ref: str) -> Repertoires:
        """Returns the repertoire trials a command's REF names: a trial's run id, or every
        repertoire trial of a grid.

        Raises:
            NotFound: REF is not an id, or names neither a repertoire trial nor a grid.
        """
        if not layout.ID_PATTERN.fullmatch(ref):  # it goes into an MLflow filter string
            raise NotFound(
                f"{ref!r} is neither a run id nor a grid id; allowed: letters, digits, '.', "
                "'_', '-'"
            )
        try:
            grid_id, parent = self.grid(ref)
        except NotFound as no_grid:
            try:
                return Repertoires([self.repertoire_trial(ref)])
            except NotFound as exc:
                raise NotFound(f"{exc} ({no_grid})") from exc
        return Repertoires(self.grid_repertoires(grid_id), grid_id, parent)

    def download(self, run_id: str, name: str, into: Path) -> Path:
        """Returns a local copy of a run's artefact `name`.

        Raises:
            NotFound: the run has no such artefact.
        """
        from mlflow.exceptions import MlflowException

        try:
            return Path(self._client.download_artifacts(run_id, name, str(into)))
        except (MlflowException, OSError) as exc:
            raise NotFound(
                f"run {run_id} has no artefact {name!r}: its trial did not finish, or the "
                "store's artefacts were moved or deleted"
            ) from exc

    def artefact_at(self, artifact_uri: str, name: str, folder: Path) -> Path | None:
        """Returns a local path to artefact `name` of the run whose artefact root is
        `artifact_uri`, or None when it has none: a `file:` root is read in place, any other
        downloaded into `folder` (a server's proxied `mlflow-artifacts:` root through this
        store). Many of these run at once on threads (a report's trials)."""
        from urllib.parse import unquote, urlparse

        from mlflow.artifacts import download_artifacts
        from mlflow.exceptions import MlflowException

        parsed = urlparse(artifact_uri)
        if parsed.scheme in ("file", ""):
            path = Path(unquote(parsed.path)) / name
            return path if path.is_file() else None
        folder.mkdir(parents=True, exist_ok=True)
        try:
            return Path(
                download_artifacts(
                    artifact_uri=f"{artifact_uri}/{name}", dst_path=folder, tracking_uri=self.uri
                )
            )
        except (MlflowException, OSError):
            return None

    def repertoire(self, run_id: str, into: Path) -> pd.DataFrame:
        """Returns the run's repertoire (a row per filled cell), checked by content.

        Raises:
            NotFound: the run has no repertoire.
            ArtefactError: it is damaged.
        """
        from linkevo.workers.store.tables import read_repertoire

        path = self.download(run_id, layout.REPERTOIRE, into)
        return read_repertoire(path, run_id, layout.REPERTOIRE)

    def walk_map(self, run_id: str, into: Path) -> pd.DataFrame | None:
        """Returns the run's walk map (`linkevo walkmap`), checked by content, or None
        when it has none.

        Raises:
            ArtefactError: it is damaged.
        """
        from linkevo.workers.store.tables import read_walk_map

        if layout.WALK_MAP not in self.artefact_names(run_id):
            return None
        return read_walk_map(self.download(run_id, layout.WALK_MAP, into), run_id)

    def walk_prediction(self, run_id: str, into: Path) -> pd.DataFrame | None:
        """Returns the run's predicted walks (`linkevo walkmodel predict`), checked by
        content, or None when it has none.

        Raises:
            ArtefactError: they are damaged.
        """
        from linkevo.workers.store.tables import read_walk_prediction

        if layout.WALK_PREDICTION not in self.artefact_names(run_id):
            return None
        return read_walk_prediction(self.download(run_id, layout.WALK_PREDICTION, into), run_id)

    def prediction_map(self, run_id: str, into: Path) -> pd.DataFrame | None:
        """Returns a SAIL trial's prediction map (`workers.walk_sail`), checked by content,
        or None when the run has none.

        Raises:
            ArtefactError: it is damaged.
        """
        from linkevo.workers.store.tables import read_prediction_map

        if layout.PREDICTION_MAP not in self.artefact_names(run_id):
            return None
        return read_prediction_map(self.download(run_id, layout.PREDICTION_MAP, into), run_id)


def latest_per_trial(runs: pd.DataFrame) -> pd.DataFrame:
    """Returns one run per trial key of a trial table: a FINISHED one if any, else the
    latest started."""
    import pandas as pd

    if runs.empty:
        return pd.DataFrame(columns=["run_id", "status", "artifact_uri", "start_time"])
    runs = runs.assign(_done=(runs.status == "FINISHED").astype(int))
    runs = runs.sort_values(["_done", "start_time"], ascending=False)
    runs = runs.drop_duplicates(f"tags.{layout.TRIAL_KEY}").drop(columns="_done")
    return runs.reset_index(drop=True)


def in_study_order(
    frame: pd.DataFrame,
    approach: str = "approach",
    fitness: str = "fitness",
    then: str | None = None,
) -> pd.DataFrame:
    """Returns `frame`'s rows by approach and fitness in the study's order (`ordered`),
    then by the numeric column `then` when given; stable otherwise."""
    import pandas as pd

    from linkevo.sim.study import APPROACHES, FITNESSES, ordered

    approaches = ordered(frame[approach].fillna(""), APPROACHES)
    fitnesses = ordered(frame[fitness].fillna(""), FITNESSES)
    keys = {
        "_approach": frame[approach].fillna("").map(approaches.index),
        "_fitness": frame[fitness].fillna("").map(fitnesses.index),
    }
    if then is not None:
        keys["_then"] = pd.to_numeric(frame[then], errors="coerce").fillna(0)
    return frame.assign(**keys).sort_values(list(keys), kind="stable").drop(columns=list(keys))
