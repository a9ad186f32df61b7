"""Tests the grid config: TOML loading, --set overrides, validation messages."""

from __future__ import annotations

from pathlib import Path

import pytest

from linkevo.orchestrator import config
from linkevo.orchestrator.config import ConfigError, GridConfig

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "grid.toml"
    path.write_text(text)
    return path


def test_presets_load_as_the_full_study_grid():
    for name in ("quick", "paper"):
        cfg = config.load(CONFIGS / f"{name}.toml")
        assert cfg.trials == 10
        assert cfg.approaches == config.STUDY_APPROACHES
        assert cfg.fitnesses == ("Fp", "Fsl")
    assert config.load(CONFIGS / "paper.toml").batch_size == 5000


def test_missing_keys_take_defaults_and_overrides_parse_as_toml(tmp_path):
    path = write(tmp_path, "trials = 2\n")
    cfg = config.load(
        path,
        [
            'approaches=["EA","MAP-LIS"]',
            "evaluations=400",
            "mode=legacy",
            "max_seconds=30",
            "options.MAP-LIS.initial_sigma=0.3",
        ],
    )
    assert cfg.trials == 2
    assert cfg.approaches == ("EA", "MAP-LIS")
    assert cfg.evaluations == 400
    assert cfg.mode == "legacy"
    assert cfg.max_seconds == 30.0
    assert cfg.options == {"MAP-LIS": {"initial_sigma": 0.3}}
    assert cfg.batch_size == GridConfig().batch_size


def test_resolved_toml_reads_back_to_an_equal_config(tmp_path):
    cfg = config.load(
        write(tmp_path, 'trials = 3\nfitnesses = ["Fsl"]\n[options.MAP-AU]\nepochs = 5\n'),
        ["max_seconds=12.5"],
    )
    again = config.load(write(tmp_path, config.to_toml(cfg)))
    assert again == cfg


@pytest.mark.parametrize(
    ("text", "overrides", "expected"),
    [
        ('approaches = ["EA", "MAP-XX"]\n', [], "'MAP-XX'.*allowed values: EA, NSGA2"),
        ("evaluations = -5\n", [], "'evaluations' = -5.*integer >= 1"),
        ("trials = 0\n", [], "'trials' = 0"),
        ('fitnesses = ["Fp2"]\n', [], "'Fp2'.*allowed values: Fp, Fsl"),
        ("mode = 'fast'\n", [], "'fast'.*paper, legacy"),
        ("cpus_per_evaluator = 0\n", [], "cpus_per_evaluator.*> 0"),
        ("trails = 3\n", [], "unknown key 'trails' \\(did you mean 'trials'\\?\\)"),
        ("approaches = []\n", [], "non-empty list"),
        ('approaches = ["EA", "EA"]\n', [], "only once"),
        ("trials = 2\n", ["batch_size"], "expected KEY=VALUE"),
        ("trials = 2\n", ["seeds=1"], "unknown key 'seeds'"),
        ("trials = 2\n", ["mode.x=1"], "only 'options.<approach>.<name>' may be dotted"),
        ("[options]\nepochs = 3\n", [], "options.epochs.*allowed tables: EA"),
        ("trials = 2\n", ['approaches=["EA"'], "not a TOML value"),
        ("trials = [1, 2\n", [], "malformed TOML"),
        ("trials = true\n", [], "'trials' = True"),
        ("surrogate = 1\n", [], '\'surrogate\' = 1.*"screen" \\(or true\\), "sail"'),
        ('surrogate = "sail"\nwalk_model = 3\n', [], "'walk_model' = 3.*run id"),
        ('walk_model = "abc"\n', [], "'walk_model'.*with surrogate = \"sail\" only"),
        (
            'fitnesses = ["Fw"]\nwalks = 99\napproaches = ["MAP-AU"]\nsurrogate = "sail"\n',
            [],
            "'surrogate'.*MAP-AU, whose descriptors are learned",
        ),
        ('fitnesses = ["Fw"]\nwalks = 9\nsurrogate = true\n', [], "'surrogate'.*MAP-Elites"),
    ],
)
def test_bad_configs_name_the_key_and_what_is_allowed(tmp_path, text, overrides, expected):
    with pytest.raises(ConfigError, match=expected):
        config.load(write(tmp_path, text), overrides)


def test_missing_file_is_a_clear_error(tmp_path):
    with pytest.raises(ConfigError, match=r"cannot read config file .*nope\.toml"):
        config.load(tmp_path / "nope.toml")


def test_identity_leaves_out_how_and_where_a_grid_runs():
    base = GridConfig(trials=2)
    moved = GridConfig(trials=2, evaluators_per_trial=3, tracking_uri="http://x", work_dir="/w")
    assert base.identity() == moved.identity()
    assert base.identity() != GridConfig(trials=2, evaluations=400).identity()


def test_identity_leaves_out_the_trial_count_so_a_grid_can_grow():
    assert GridConfig(trials=10).identity() == GridConfig(trials=30).identity()


def test_flatten_turns_tables_into_dotted_params():
    assert config.flatten({"a": 1, "options": {"b": [1, 2]}}) == {
        "a": "1",
        "options.b": "[1, 2]",
    }


def test_walk_rerank_is_part_of_the_grid_only_when_on():
    plain = GridConfig()
    assert "walk_rerank" not in plain.identity()
    assert GridConfig(walk_rerank=0).identity() == plain.identity()
    assert GridConfig(walk_rerank=20).identity() == {**plain.identity(), "walk_rerank": 20}
    with pytest.raises(ConfigError, match="config key 'walk_rerank' = -1 is invalid"):
        GridConfig(walk_rerank=-1)
    with pytest.raises(ConfigError, match="allowed: 0 to 1000"):
        GridConfig(walk_rerank=5000)
