"""Checks the cluster files in infra/ (no Kubernetes or Docker runs here): they parse, and
their images, ports, volumes and paths agree with each other, pyproject.toml and the docs."""

from __future__ import annotations

import re
import shlex
import tomllib
from pathlib import Path

import pytest
import yaml
from packaging.requirements import Requirement

REPO = Path(__file__).resolve().parents[1]
INFRA = REPO / "infra"


def load(relative: str) -> dict:
    docs = list(yaml.safe_load_all((INFRA / relative).read_text()))
    assert len(docs) == 1 and isinstance(docs[0], dict), relative
    return docs[0]


def requirement(name: str) -> Requirement:
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    found = [Requirement(r) for r in project["dependencies"] if Requirement(r).name == name]
    assert found, f"{name} is not a dependency"
    return found[0]


@pytest.mark.parametrize(
    "path", sorted(p.relative_to(INFRA).as_posix() for p in INFRA.rglob("*.yaml"))
)
def test_every_infra_file_parses(path: str) -> None:
    assert load(path)


def test_the_rayjob_matches_the_mlflow_server_and_the_shared_volume() -> None:
    job = load("k8s/rayjob.yaml")
    assert job["kind"] == "RayJob" and job["apiVersion"] == "ray.io/v1"
    spec = job["spec"]["rayClusterSpec"]
    assert requirement("ray").specifier.contains(spec["rayVersion"])
    head = spec["headGroupSpec"]
    assert head["rayStartParams"]["num-cpus"] == "0"  # the driver only; trials on workers
    pods = [head["template"]["spec"]] + [g["template"]["spec"] for g in spec["workerGroupSpecs"]]
    assert len({c["image"] for pod in pods for c in pod["containers"]}) == 1
    for pod in pods:
        volumes = {v["name"] for v in pod["volumes"]}
        for container in pod["containers"]:
            mounts = {m["name"]: m["mountPath"] for m in container["volumeMounts"]}
            assert set(mounts) <= volumes
            assert mounts["shared"] == "/shared"
    entry = shlex.split(job["spec"]["entrypoint"])
    uri = entry[entry.index("--tracking-uri") + 1]
    assert uri == "http://mlflow:5000"
    assert 'work_dir="/shared/linkevo"' in entry  # on the volume every pod mounts
    assert job["spec"]["runtimeEnvYAML"].count(uri) == 1  # workers get the same URI


def test_the_compose_server_wires_postgres_minio_and_the_published_port() -> None:
    compose = load("mlflow/docker-compose.yaml")
    services = compose["services"]
    mlflow = services["mlflow"]
    tag = mlflow["image"].rsplit(":v", 1)[1]
    assert requirement("mlflow").specifier.contains(tag)
    command = mlflow["command"]
    assert mlflow["ports"] == ["5000:5000"] and "--port 5000" in command
    pg = services["postgres"]["environment"]
    backend = re.search(r"--backend-store-uri (\S+)", command).group(1)
    assert backend == (
        f"postgresql+psycopg2://{pg['POSTGRES_USER']}:{pg['POSTGRES_PASSWORD']}"
        f"@postgres:5432/{pg['POSTGRES_DB']}"
    )
    bucket = re.search(r"--artifacts-destination s3://([\w-]+)/", command).group(1)
    assert f"mc mb --ignore-existing s3/{bucket}" in services["create-bucket"]["entrypoint"]
    assert mlflow["environment"]["MLFLOW_S3_ENDPOINT_URL"] == "http://minio:9000"
    minio = services["minio"]["environment"]
    assert mlflow["environment"]["AWS_ACCESS_KEY_ID"] == minio["MINIO_ROOT_USER"]
    assert mlflow["environment"]["AWS_SECRET_ACCESS_KEY"] == minio["MINIO_ROOT_PASSWORD"]
    named = {v.split(":")[0] for s in services.values() for v in s.get("volumes", [])}
    assert named == set(compose["volumes"])


def test_the_ray_up_file_starts_a_head_and_workers_on_one_port() -> None:
    cluster = load("ray/cluster.yaml")
    assert cluster["provider"]["type"] == "local"
    assert len(cluster["provider"]["worker_ips"]) == cluster["max_workers"]
    head = " ".join(cluster["head_start_ray_commands"])
    port = re.search(r"ray start --head --port=(\d+)", head).group(1)
    workers = " ".join(cluster["worker_start_ray_commands"])
    assert f"--address=$RAY_HEAD_IP:{port}" in workers


def test_the_docs_name_the_files_and_the_server_port() -> None:
    readme = (INFRA / "README.md").read_text()
    for path in INFRA.rglob("*.yaml"):
        assert path.relative_to(INFRA).as_posix() in readme
    grid_doc = (REPO / "docs" / "grid.md").read_text()
    assert "infra/k8s/rayjob.yaml" in grid_doc and "infra/mlflow/" in grid_doc
    assert "http://<mlflow-host>:5000" in readme
