"""Provides a local cluster started the way a real one is: PostgreSQL, an MLflow server on it,
and a Ray head plus worker nodes, each its own `ray start` process tree.

`up` starts, in order:
1. PostgreSQL (the `postgres` of Debian's `postgresql` package) in a throwaway data
   directory, listening on 127.0.0.1 only, trust authentication, database `mlflow`;
2. `mlflow server` on that database with proxied artefacts (`--serve-artifacts`) in
   `<dir>/artifacts`, on 127.0.0.1;
3. `ray start --head --block` (0 CPUs by default, so trials run on the workers) and N
   `ray start --block` worker nodes with `cpus_per_worker` CPUs each.

Every process is started in a session of its own; the session ids, ports and node ids go to
`<dir>/cluster.json`, so `down` (or `stop_node`, to take a worker away mid-grid) signals
exactly those process trees, as `ray stop` would, and nothing else on the machine.
Ray keeps token authentication on with a token file in `<dir>`; a driver needs the two
environment variables of `ClusterState.env` (`linkevo cluster env` prints them).
"""

from __future__ import annotations

import contextlib
import json
import os
import secrets
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from linkevo.orchestrator.process_sessions import (
    STOP_TIMEOUT_S,
    ClusterError,
    alive_sessions,
    answers,
    free_port,
    in_use,
    processes_using,
    session_members,
    spawn,
    stop_session,
)
from linkevo.workers.store.artifacts import write_json_atomic, write_text_atomic

STATE_FILE = "cluster.json"
TOKEN_FILE = "ray_auth_token"
DATABASE = "mlflow"
DB_USER = "linkevo"
START_TIMEOUT_S = 120.0


@dataclass(frozen=True)
class ClusterSettings:
    """What `up` starts.

    Attributes:
        dir: the cluster's folder (state, logs, artefacts, Ray token).
        workers: Ray worker nodes (>= 1).
        cpus_per_worker: CPUs each worker node offers (>= 1).
        head_cpus: CPUs the head node offers (0: it only schedules).
        object_store_mb: object store per node, MiB (>= 78, Ray's minimum).
        mlflow_workers: uvicorn workers of the MLflow server (>= 1).
        postgres_port, mlflow_port, ray_port: 0 takes a free port.
    """

    dir: Path
    workers: int = 2
    cpus_per_worker: int = 1
    head_cpus: int = 0
    object_store_mb: int = 100
    mlflow_workers: int = 2
    postgres_port: int = 0
    mlflow_port: int = 0
    ray_port: int = 0

    def __post_init__(self) -> None:
        minimum = {"workers": 1, "cpus_per_worker": 1, "head_cpus": 0}
        minimum |= {"object_store_mb": 78, "mlflow_workers": 1}
        for name, low in minimum.items():
            value = getattr(self, name)
            if not isinstance(value, int) or value < low:
                raise ClusterError(f"{name} must be an integer >= {low}, got {value!r}")
        for name in ("postgres_port", "mlflow_port", "ray_port"):
            value = getattr(self, name)
            if not isinstance(value, int) or not 0 <= value <= 65535:
                raise ClusterError(f"{name} must be 0 (any free port) or 1..65535, got {value!r}")


@dataclass
class Node:
    """One Ray node: its `ray start` session (= the session leader's pid) and node id."""

    role: str
    sid: int
    node_id: str
    cpus: int


@dataclass
class ClusterState:
    """A started cluster, as written to `<dir>/cluster.json`."""

    dir: str
    postgres_port: int
    mlflow_port: int
    ray_port: int
    pg_data: str
    ray_temp: str
    postgres_user: str
    mlflow_sid: int
    nodes: list[Node] = field(default_factory=list)

    @property
    def tracking_uri(self) -> str:
        """The MLflow server, for `--tracking-uri`."""
        return f"http://127.0.0.1:{self.mlflow_port}"

    @property
    def address(self) -> str:
        """The Ray head, for `--address`."""
        return f"127.0.0.1:{self.ray_port}"

    @property
    def database_uri(self) -> str:
        """The PostgreSQL database behind the MLflow server."""
        return f"postgresql+psycopg2://{DB_USER}@127.0.0.1:{self.postgres_port}/{DATABASE}"

    @property
    def env(self) -> dict[str, str]:
        """The environment a Ray driver needs to join (token authentication)."""
        return {"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN_PATH": str(Path(self.dir) / TOKEN_FILE)}

    @property
    def workers(self) -> list[Node]:
        """The worker nodes, in start order."""
        return [n for n in self.nodes if n.role == "worker"]

    def save(self) -> None:
        """Writes the state file atomically."""
        write_json_atomic(Path(self.dir) / STATE_FILE, asdict(self))

    @staticmethod
    def load(folder: Path) -> ClusterState | None:
        """Returns the state in `folder`, or None when no cluster was started there."""
        path = Path(folder) / STATE_FILE
        if not path.exists():
            return None
        raw = json.loads(path.read_text())
        raw["nodes"] = [Node(**n) for n in raw["nodes"]]
        return ClusterState(**raw)


def up(settings: ClusterSettings) -> ClusterState:
    """Starts PostgreSQL, the MLflow server and the Ray nodes; returns the saved state.

    On any failure everything already started is stopped again before the error is raised.

    Raises:
        ClusterError: a cluster is already up in `settings.dir`, a port is taken, a program
            is missing, or a part did not start in time (the message names its log).
    """
    folder = Path(settings.dir).resolve()
    previous = ClusterState.load(folder)
    if previous is not None and alive_sessions(_sessions(previous)):
        raise ClusterError(
            f"a cluster is already up in {folder}; stop it with: {_down_hint(folder)}"
        )
    ports = {
        name: free_port(getattr(settings, name), name)
        for name in ("postgres_port", "mlflow_port", "ray_port")
    }
    _postgres_bin()  # fails early when PostgreSQL is not installed
    (folder / "logs").mkdir(parents=True, exist_ok=True)
    write_text_atomic(folder / TOKEN_FILE, secrets.token_hex(32) + "\n")
    os.chmod(folder / TOKEN_FILE, 0o600)
    state = ClusterState(
        dir=str(folder),
        pg_data=tempfile.mkdtemp(prefix="linkevo-pg-"),
        ray_temp=tempfile.mkdtemp(prefix="linkevo-ray-"),
        postgres_user=_postgres_user(),
        mlflow_sid=0,
        **ports,
    )
    state.save()
    try:
        _start_postgres(state)
        _start_mlflow(state, settings.mlflow_workers)
        _start_ray(state, settings)  # while the MLflow server creates its tables
        _wait_for_mlflow(state)
    except BaseException:
        down(folder)
        raise
    return state


def down(folder: Path) -> list[str]:
    """Stops every process of the cluster in `folder`, removes its throwaway data and state.

    Returns:
        What was stopped, one line each (empty when no cluster was up there).

    Raises:
        ClusterError: a process or port is still there after the stop (the message names it).
    """
    state = ClusterState.load(Path(folder).resolve())
    if state is None:
        return []
    stopped = []
    for node in reversed(state.nodes):  # workers first, the head last
        stop_session(node.sid)
        stopped.append(f"ray {node.role} {node.node_id[:8] or '(starting)'}")
    if state.mlflow_sid:
        stop_session(state.mlflow_sid)
        stopped.append("mlflow server")
    if Path(state.pg_data, "PG_VERSION").exists():
        _pg(
            state,
            "pg_ctl",
            f"stop -D {state.pg_data} -m fast -w -t {STOP_TIMEOUT_S:.0f}",
            check=False,
        )
        stopped.append("postgresql")
        with contextlib.suppress(OSError):  # the server's log outlives its data directory
            shutil.copyfile(
                Path(state.pg_data, "server.log"), Path(state.dir, "logs", "postgresql.log")
            )
    left = alive_sessions(_sessions(state)) + processes_using(state.pg_data, state.ray_temp)
    if left:
        raise ClusterError(f"processes still running after the stop: {sorted(set(left))}")
    busy = [p for p in (state.postgres_port, state.mlflow_port, state.ray_port) if in_use(p)]
    if busy:
        raise ClusterError(f"ports still in use after the stop: {busy}")
    shutil.rmtree(state.pg_data, ignore_errors=True)
    shutil.rmtree(state.ray_temp, ignore_errors=True)
    Path(state.dir, STATE_FILE).unlink()
    return stopped


def stop_node(state: ClusterState, node: Node, force: bool = False) -> None:
    """Stops one Ray node's processes (its `ray start` session), as `ray stop` on that node.

    Without `force` the node drains first (Ray lets its running tasks end, up to 30 s);
    with it every process is killed at once (`ray stop --force`; a machine that dies).
    """
    stop_session(node.sid, force)
    state.nodes = [n for n in state.nodes if n.sid != node.sid]
    state.save()


def _start_postgres(state: ClusterState) -> None:
    if state.postgres_user:
        shutil.chown(state.pg_data, user=state.postgres_user)
    data = state.pg_data
    _pg(state, "initdb", f"-D {data} -U {DB_USER} --auth=trust -E UTF8 --no-instructions")
    listen = f"-h 127.0.0.1 -p {state.postgres_port} -k {data}"
    _pg(
        state,
        "pg_ctl",
        f"start -D {data} -w -t {START_TIMEOUT_S:.0f} -l {data}/server.log",
        "-o",
        listen,
    )
    _pg(state, "createdb", f"-h 127.0.0.1 -p {state.postgres_port} -U {DB_USER} {DATABASE}")


def _start_mlflow(state: ClusterState, workers: int) -> None:
    artifacts = Path(state.dir, "artifacts")
    artifacts.mkdir(exist_ok=True)
    command = [
        sys.executable,
        "-m",
        "mlflow",
        "server",
        "--backend-store-uri",
        state.database_uri,
        "--serve-artifacts",
        "--artifacts-destination",
        str(artifacts),
        "--host",
        "127.0.0.1",
        "--port",
        str(state.mlflow_port),
        "--workers",
        str(workers),
        "--gunicorn-opts",
        "--log-level warning",
    ]
    # gunicorn, not the default uvicorn: through uvicorn each request on a kept-alive
    # connection (the MLflow client's) took about 60 ms on loopback against 12 ms here
    # (docs/scale.md). The background job runner (GenAI jobs) is not needed by linkevo.
    env = {**os.environ, "MLFLOW_SERVER_ENABLE_JOB_EXECUTION": "false"}
    state.mlflow_sid = spawn(command, Path(state.dir, "logs", "mlflow.log"), env)
    state.save()


def _wait_for_mlflow(state: ClusterState) -> None:
    health = f"{state.tracking_uri}/health"
    what = f"the MLflow server at {health}"
    _wait(lambda: answers(health), what, "mlflow.log", state, state.mlflow_sid)


def _start_ray(state: ClusterState, settings: ClusterSettings) -> None:
    ray = str(Path(sys.executable).with_name("ray"))
    env = {**os.environ, **state.env, "RAY_USAGE_STATS_ENABLED": "0"}
    common = [
        "--block",
        "--node-ip-address",
        "127.0.0.1",
        "--disable-usage-stats",
        "--object-store-memory",
        str(settings.object_store_mb * 2**20),
    ]
    head = [
        ray,
        "start",
        "--head",
        "--port",
        str(state.ray_port),
        "--num-cpus",
        str(settings.head_cpus),
        "--include-dashboard",
        "false",
        "--temp-dir",
        state.ray_temp,
        *common,
    ]
    worker = [
        ray,
        "start",
        "--address",
        state.address,
        "--num-cpus",
        str(settings.cpus_per_worker),
        *common,
    ]
    # One node at a time: raylets that start together on one host time out registering.
    plan = [("head", head, settings.head_cpus)]
    plan += [("worker", worker, settings.cpus_per_worker)] * settings.workers
    for role, command, cpus in plan:
        name = "ray-head.log" if role == "head" else f"ray-worker-{len(state.nodes)}.log"
        log = Path(state.dir, "logs", name)
        node = Node(role=role, sid=spawn(command, log, env), node_id="", cpus=cpus)
        state.nodes.append(node)
        state.save()
        _wait(
            lambda log=log: "Ray runtime started" in log.read_text(errors="replace"),
            f"the Ray {role} node",
            name,
            state,
            node.sid,
        )
        node.node_id = _node_id(node.sid)
        state.save()
    _wait(lambda: _alive_nodes(state) == len(plan), "every Ray node", "ray-head.log", state)


def _alive_nodes(state: ClusterState) -> int:
    """How many nodes the Ray cluster reports alive (asked by a short-lived driver)."""
    code = "import ray; ray.init(address=%r); print(sum(n['Alive'] for n in ray.nodes()))"
    done = subprocess.run(
        [sys.executable, "-c", code % state.address],
        capture_output=True,
        text=True,
        env={**os.environ, **state.env},
    )
    lines = done.stdout.split()
    return int(lines[-1]) if done.returncode == 0 and lines else -1


def _wait(ready, what: str, log: str, state: ClusterState, sid: int = 0) -> None:
    """Polls `ready()` until true; fails when `sid`'s leader exits or after the timeout."""
    deadline = time.monotonic() + START_TIMEOUT_S
    path = Path(state.dir, "logs", log)
    while not ready():
        if sid and sid not in session_members(sid):
            tail = path.read_text(errors="replace").strip().splitlines()[-1:]
            raise ClusterError(f"{what} exited while starting ({' '.join(tail)}); see {path}")
        if time.monotonic() > deadline:
            raise ClusterError(f"{what} did not start within {START_TIMEOUT_S:.0f} s; see {path}")
        time.sleep(0.2)


def _node_id(sid: int) -> str:
    """Returns the Ray node id of the raylet in session `sid`."""
    deadline = time.monotonic() + START_TIMEOUT_S
    while time.monotonic() < deadline:
        for pid in session_members(sid):
            try:
                args = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
            except OSError:
                continue
            if args and args[0].endswith(b"/raylet"):
                for arg in args:
                    if arg.startswith(b"--node_id="):
                        return arg.split(b"=", 1)[1].decode()
        time.sleep(0.2)
    raise ClusterError(f"no raylet appeared in the Ray node's process session {sid}")


def _sessions(state: ClusterState) -> list[int]:
    return [n.sid for n in state.nodes] + ([state.mlflow_sid] if state.mlflow_sid else [])


def _postgres_bin() -> Path:
    """The folder of PostgreSQL's server programs (Debian keeps them off PATH)."""
    found = shutil.which("pg_ctl")
    if found:
        return Path(found).resolve().parent
    versions = sorted(Path("/usr/lib/postgresql").glob("*/bin/pg_ctl"))
    if versions:
        return versions[-1].parent
    raise ClusterError(
        "PostgreSQL's server programs (pg_ctl, initdb) were not found; "
        "install them with: apt-get install postgresql"
    )


def _postgres_user() -> str:
    """'' normally; 'postgres' for root, since PostgreSQL refuses to run as root."""
    if os.geteuid() != 0:
        return ""
    try:
        import pwd

        pwd.getpwnam("postgres")
    except KeyError as exc:
        raise ClusterError(
            "PostgreSQL refuses to run as root and there is no 'postgres' user to run it as; "
            "run linkevo cluster up as a normal user"
        ) from exc
    return "postgres"


def _pg(state: ClusterState, program: str, args: str, *more: str, check: bool = True) -> None:
    """Runs a PostgreSQL program with whitespace-separated `args` (then `more` as they are),
    as the `postgres` user when this is root."""
    command = [str(_postgres_bin() / program), *args.split(), *more]
    if state.postgres_user:
        command = ["runuser", "-u", state.postgres_user, "--", *command]
    done = subprocess.run(command, capture_output=True, text=True)
    if check and done.returncode != 0:
        raise ClusterError(f"{' '.join(command)} failed:\n{done.stderr.strip()}")


def _down_hint(folder: Path) -> str:
    return f"linkevo cluster down --dir {folder}"
