"""`linkevo hexapod calibrate` under faults, on a real store: outputs it could not write or
would overwrite, and field trials it cannot use, refused before the fit (no walk) with one
line; nothing written."""

from __future__ import annotations

import pytest

from linkevo.hardware.field_trial import log_field_trial
from linkevo.workers.store.linkages import SourceLinkage
from linkevo.workers.store.run_layout import REAL
from linkevo.workers.store.tracking import ensure_experiment
from tests.helpers.faults import refused, snapshot

LEG = "tests/data/sound_leg.json"


@pytest.fixture(scope="module")
def trials(tmp_path_factory):
    """A store with two real field trials on the flat floor and one on a kitchen floor
    (distances typed in: calibrate refuses before it walks any)."""
    import json
    from pathlib import Path

    root = tmp_path_factory.mktemp("faults-calibrate")
    uri = f"sqlite:///{root / 'mlflow.db'}"
    experiment = ensure_experiment(uri)
    document = json.loads(
        (Path(__file__).resolve().parents[1] / "data" / "sound_leg.json").read_text()
    )
    runs = {}
    for name, floor in (("a", "flat"), ("b", "flat"), ("kitchen", "kitchen tiles")):
        source = SourceLinkage(f"run-{name}", None, experiment, "MAP-LIS", "Fp", document, "")
        runs[name] = log_field_trial(
            uri,
            source,
            robot="first",
            floor=floor,
            distances=[30.0],
            params={"seconds": "2.0", "repeats": "1", "simulated": REAL},
        )
    return uri, runs, root


def calibrate(uri: str, out, *runs: str) -> list[str]:
    return [
        *f"hexapod calibrate --params speed_rpm --tracking-uri {uri} --out {out}".split(),
        "--trials",
        *runs,
    ]


def test_a_trial_on_a_floor_the_simulator_lacks_is_refused(trials, tmp_path, capsys):
    uri, runs, _ = trials
    said = refused(calibrate(uri, tmp_path / "r.toml", runs["a"], runs["kitchen"]), capsys)
    assert f"--trials {runs['kitchen']}: walked on the floor 'kitchen tiles'" in said
    assert "allowed: trials on flat, carpet" in said
    assert snapshot(tmp_path) == {}


def test_an_output_that_exists_is_refused_unless_forced(trials, tmp_path, capsys):
    uri, runs, _ = trials
    out = tmp_path / "robot.toml"
    out.write_text("# the user's own config\n")
    said = refused(calibrate(uri, out, runs["a"], runs["b"]), capsys)
    assert f"--out {str(out)!r} exists; add --force to replace it" in said
    assert out.read_text() == "# the user's own config\n"


def test_an_output_that_cannot_be_written_is_refused_before_the_fit(trials, tmp_path, capsys):
    uri, runs, _ = trials
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    said = refused(calibrate(uri, blocker / "robot.toml", runs["a"], runs["b"]), capsys)
    assert f"{str(blocker)!r} is a file, not a folder" in said
