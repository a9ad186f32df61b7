"""Provides MLflow store resolution and the experiment set-up shared by every writer."""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
from collections.abc import Iterator
from pathlib import Path

from linkevo.sim.errors import LinkevoError
from linkevo.workers.store import run_layout as layout

DEFAULT_STORE_DIR = Path("runs")
"""Where the embedded store lives, relative to the working directory, unless told."""
DEFAULT_EXPERIMENT = "linkevo"
EXPERIMENT_KIND = {"mlflow.experimentKind": "custom_model_development"}
"""Opens the experiment in the MLflow UI's runs table (model development), not its GenAI
view: a grid's runs are trials with metrics, not traces."""
EXPERIMENT_DESCRIPTION = (
    "linkevo: evolved leg linkages for a hexapod (Evolution of linkages for prototyping of "
    "linkage based robots). Each grid is a parent run `grid-<grid_id>` whose description "
    "says what it ran; its nested runs are the trials (tags approach, fitness, trial_key; "
    "metrics best_loss, coverage, qd_score per iteration; the repertoire or population and "
    "the best linkage as artefacts). Field trials, real and simulated, are runs tagged "
    "`linkevo.kind = field_trial`. Compare trials by best_loss within one fitness; "
    "`linkevo report GRID_ID` gives the study's figures and statistics."
)
"""The experiment's description in the MLflow UI (`mlflow.note.content`)."""
RUNS_VIEW_KEY = "linkevo-trials"
"""The name of the runs table's view that `linkevo ui` opens (`RUNS_VIEW`)."""
RUNS_VIEW = {
    "searchFilter": f"tags.`{layout.KIND}` = '{layout.TRIAL}'",
    "orderByKey": "tags.`mlflow.runName`",
    "orderByAsc": True,
    "selectedColumns": [
        *(f"tags.`{tag}`" for tag in (layout.APPROACH, layout.FITNESS, layout.TRIAL_INDEX)),
        *(f"metrics.`{metric}`" for metric in ("best_loss", "coverage", "qd_score")),
        f"tags.`{layout.GRID_ID}`",
    ],
    "groupBy": {
        "aggregateFunction": "min",
        "groupByKeys": [{"mode": "tag", "groupByData": layout.GRID_ID}],
    },
}
"""The runs table as `linkevo ui` opens it: every trial (grids' nested runs, not folded
under their parent), with its approach, fitness, trial index, best loss, coverage and
QD-score as columns. Stored as MLflow's own shared view (an experiment tag
`mlflow.sharedViewState.<key>`, what the UI's "Share" button writes) and opened with
`?viewStateShareKey=<key>`; the user's own column choices are untouched."""
EXPERIMENT_TAGS = EXPERIMENT_KIND | {
    layout.NOTE: EXPERIMENT_DESCRIPTION,
    f"mlflow.sharedViewState.{RUNS_VIEW_KEY}": json.dumps(RUNS_VIEW),
}
"""Every tag the linkevo experiment carries; `ensure_experiment` adds the missing ones."""


def default_tracking_uri(store_dir: Path | None = None) -> str:
    """Returns the absolute sqlite URI of the embedded store (`<store_dir>/mlflow.db`)."""
    root = (store_dir or DEFAULT_STORE_DIR).resolve()
    return f"sqlite:///{root / 'mlflow.db'}"


class TrackingUriError(LinkevoError, ValueError):
    """A tracking URI linkevo cannot use; the message names it and what is allowed."""


TRACKING_SCHEMES: tuple[str, ...] = ("http", "https", "sqlite", "postgresql", "mysql", "file")
"""URI schemes (a `+driver` suffix allowed, e.g. postgresql+psycopg2) MLflow serves here."""


def resolve_tracking_uri(uri: str | None = None) -> str:
    """Returns an absolute tracking URI.

    Order: the explicit `uri`, then `MLFLOW_TRACKING_URI`, then the embedded default.
    Relative sqlite paths are made absolute (MLflow resolves them against each process's
    working directory, which differs between the driver and Ray workers); a bare path is
    taken as a directory for an embedded store.

    Raises:
        TrackingUriError: for a scheme outside `TRACKING_SCHEMES`.
    """
    uri = uri or os.environ.get("MLFLOW_TRACKING_URI") or default_tracking_uri()
    scheme = uri.partition("://")[0].partition("+")[0] if "://" in uri else ""
    if scheme and scheme not in TRACKING_SCHEMES:
        raise TrackingUriError(
            f"tracking URI {uri!r}: scheme {scheme!r} is not supported; allowed: an "
            "http(s):// MLflow server, a sqlite:///ABS/PATH.db store, a database URI "
            "(postgresql://, mysql://), or a folder for an embedded store"
        )
    if uri.startswith("sqlite:///"):
        path = Path(uri.removeprefix("sqlite:///"))
        return f"sqlite:///{path.resolve()}"
    if "://" not in uri:
        return default_tracking_uri(Path(uri))
    return uri


def require_store(uri: str) -> str:
    """Returns `uri` when it names a store that exists (a server or database is taken as
    existing; a sqlite file must be there), so that reading never creates a store.

    Raises:
        TrackingUriError: naming the missing file and how to make one.
    """
    if uri.startswith("sqlite:///") and not Path(uri.removeprefix("sqlite:///")).is_file():
        raise TrackingUriError(
            f"no MLflow store at {uri.removeprefix('sqlite:///')}; run a grid first "
            "(linkevo grid configs/quick.toml) or pass --tracking-uri"
        )
    check_store_file(uri)
    follow_moved_store(uri)
    return uri


SQLITE_MAGIC = b"SQLite format 3\x00"


def check_store_file(uri: str) -> None:
    """Refuses an embedded sqlite store that is damaged, before anything reads or writes it
    (a missing file is fine: a writer creates it).

    MLflow itself would re-create the schema in an emptied file (so a `--resume` would run
    the whole grid again beside its orphaned files) and fail deep inside SQLAlchemy on a
    truncated one. Checked here: a file of zero bytes, a file that is not SQLite, and one
    shorter than the page count its header states (a truncated copy or a full disk).

    Raises:
        TrackingUriError: naming the file, what is wrong and what to do.
    """
    if not uri.startswith("sqlite:///"):
        return
    path = Path(uri.removeprefix("sqlite:///"))
    try:
        size = path.stat().st_size
        with open(path, "rb") as handle:
            header = handle.read(100)
    except FileNotFoundError:
        return
    except OSError as exc:
        raise TrackingUriError(f"cannot read the MLflow store {path}: {exc.strerror}") from exc
    remedy = (
        "restore it from a backup (or the copy the grid ran on), or move it away to start "
        "a new store; the trial folders and artefacts beside it are kept"
    )
    if size == 0:
        raise TrackingUriError(f"the MLflow store {path} is empty (0 bytes); {remedy}")
    if not header.startswith(SQLITE_MAGIC) or len(header) < 100:
        raise TrackingUriError(f"{path} is not an MLflow (SQLite) store; {remedy}")
    page_size = int.from_bytes(header[16:18], "big")
    page_size = 65536 if page_size == 1 else page_size
    pages = int.from_bytes(header[28:32], "big")
    stated = header[92:96] == header[24:28]  # the header's page count is current
    if stated and size < pages * page_size:
        raise TrackingUriError(
            f"the MLflow store {path} is damaged: {size:,} bytes where its header states "
            f"{pages * page_size:,} (truncated, e.g. by a full disk or a partial copy); "
            f"{remedy}"
        )


ARTEFACT_FOLDER = "mlartifacts"
"""The folder beside an embedded store's database that holds its runs' artefacts."""
_LOCATIONS = (
    ("experiments", "artifact_location"),
    ("runs", "artifact_uri"),
    ("logged_models", "artifact_location"),
)
"""Where MLflow's sqlite schema records artefact locations (absolute URIs)."""


def artifact_root_for(uri: str) -> str | None:
    """Returns the local artifact folder URI for an embedded sqlite store, else None."""
    if uri.startswith("sqlite:///"):
        return (Path(uri.removeprefix("sqlite:///")).parent / ARTEFACT_FOLDER).as_uri()
    return None


def follow_moved_store(uri: str) -> str | None:
    """Re-anchors an embedded store that was moved or copied (with its `mlartifacts`
    folder) to the artefacts beside it; returns the folder it recorded before, or None
    when nothing had moved.

    MLflow records absolute artefact locations, so a moved store would look for its
    artefacts where it was, and a copy would write into the original's files. linkevo's
    own stores keep their artefacts in the `mlartifacts` folder beside the database: a
    recorded location of that form in another folder is rewritten, under the store's
    lock, to the one beside the database now.

    Raises:
        TrackingUriError: the database was copied or moved without its artefacts (the
            folder it recorded still exists and none lies beside it): naming both
            folders and what to do.
    """
    import sqlite3
    from urllib.parse import unquote, urlparse

    if not uri.startswith("sqlite:///"):
        return None
    database = Path(uri.removeprefix("sqlite:///"))
    here = artifact_root_for(uri)
    try:
        with contextlib.closing(sqlite3.connect(f"file:{database}?mode=ro", uri=True)) as db:
            recorded = {row[0] for row in db.execute("select artifact_location from experiments")}
    except sqlite3.Error:
        return None  # a fresh or foreign file: `check_store_file` and MLflow speak for it
    ours = {loc for loc in recorded if loc.startswith("file://")}
    moved = sorted(loc for loc in ours if loc.endswith(f"/{ARTEFACT_FOLDER}") and loc != here)
    if not moved:
        return None
    old = moved[0]
    old_folder = Path(unquote(urlparse(old).path))
    if old_folder.is_dir() and not (database.parent / ARTEFACT_FOLDER).is_dir():
        raise TrackingUriError(
            f"the store {database} records its artefacts in {old_folder}, not beside it: it "
            f"was copied or moved without them. Copy {old_folder} to "
            f"{database.parent / ARTEFACT_FOLDER} (or move the store back), so that this "
            "store never writes into the other's files"
        )
    with store_lock(uri), contextlib.closing(sqlite3.connect(database)) as db, db:
        for table, column in _LOCATIONS:
            db.execute(
                f"update {table} set {column} = ? || substr({column}, ?) "
                f"where {column} = ? or substr({column}, 1, ?) = ?",
                (here, len(old) + 1, old, len(old) + 1, f"{old}/"),
            )
    return old


@contextlib.contextmanager
def store_lock(uri: str) -> Iterator[None]:
    """Holds an exclusive lock on an embedded sqlite store (`<db>.lock` beside it) while
    the block runs; no lock is needed for a tracking server, which serialises itself.

    MLflow creates or migrates a sqlite schema on a client's first use, in several
    statements; two processes doing that at once fail (`duplicate column name`) and can
    leave the store half-migrated. Every process that may be the first to open a store
    opens it inside this lock.
    """
    if not uri.startswith("sqlite:///"):
        yield
        return
    database = Path(uri.removeprefix("sqlite:///"))
    database.parent.mkdir(parents=True, exist_ok=True)
    with open(f"{database}.lock", "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def ensure_experiment(uri: str, name: str = DEFAULT_EXPERIMENT) -> str:
    """Creates the store and experiment if needed (driver side, before any fan-out), as a
    model-development experiment (`EXPERIMENT_KIND`) with a description and the runs
    table's view (`EXPERIMENT_TAGS`, added to an older experiment that lacks them);
    returns its id.

    The store's schema and the experiment are created under `store_lock`, so launches
    started together on a fresh store queue up instead of racing.
    """
    from mlflow.tracking import MlflowClient

    check_store_file(uri)
    follow_moved_store(uri)
    with store_lock(uri):
        client = MlflowClient(tracking_uri=uri)
        experiment = client.get_experiment_by_name(name)
        if experiment is None:
            return client.create_experiment(
                name, artifact_location=artifact_root_for(uri), tags=EXPERIMENT_TAGS
            )
        for key, value in EXPERIMENT_TAGS.items():  # an older linkevo's experiment
            stored = experiment.tags.get(key)
            if stored is None or (stored != value and key != layout.NOTE):  # keep user notes
                client.set_experiment_tag(experiment.experiment_id, key, value)
        return experiment.experiment_id


def ui_address(base: str, experiment_id: str | None) -> str:
    """Returns the MLflow UI address `linkevo ui` opens: the experiment's runs table in
    the model-training view (`workflowType=machine_learning`, which MLflow otherwise keeps
    per browser, defaulting to GenAI) with `RUNS_VIEW`; the experiment list when the
    store holds no linkevo experiment yet."""
    if experiment_id is None:
        return f"{base}/#/experiments"
    query = f"workflowType=machine_learning&viewStateShareKey={RUNS_VIEW_KEY}"
    return f"{base}/#/experiments/{experiment_id}/runs?{query}"
