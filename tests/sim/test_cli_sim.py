"""Tests for `linkevo eval` and `linkevo show`, run as a user would run them."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from linkevo import sim
from linkevo.orchestrator.cli import main
from linkevo.sim.linkage.fitness import named_target
from linkevo.sim.linkage.linkage_doc import to_document


@pytest.fixture
def linkevo(capsys, monkeypatch):
    """Runs the CLI in this process from a folder; returns (exit code, stdout, stderr)."""

    def run(*args: str, cwd) -> subprocess.CompletedProcess:
        monkeypatch.chdir(cwd)
        code = main(list(args))
        out, err = capsys.readouterr()
        return subprocess.CompletedProcess(args, code, out, err)

    return run


def test_console_entry_point_runs(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "linkevo.orchestrator", "eval", "missing.npy", "--out", "r.npz"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 2
    assert "must be an existing .npy file" in done.stderr


@pytest.fixture(scope="module")
def genome_file(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cli")
    genomes = sim.random_genomes(np.random.default_rng(3), 64)
    np.save(folder / "genomes.npy", genomes)
    return folder / "genomes.npy", genomes


@pytest.mark.parametrize("fitness", ["Fp", "Fp2", "Fsl"])
def test_eval_writes_the_documented_arrays(linkevo, genome_file, tmp_path, fitness):
    path, genomes = genome_file
    out = tmp_path / "result.npz"
    done = linkevo("eval", str(path), "--fitness", fitness, "--out", str(out), cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    result = np.load(out)
    expected = sim.evaluate(genomes, fitness)
    np.testing.assert_array_equal(result["loss"], expected.loss)
    assert result["loss"].shape == ((64,) if fitness != "Fp2" else (64, 2))
    assert result["valid"].shape == (64, 40) and result["valid"].dtype == bool
    for name in ("error", "angle_error", "foot_x", "foot_y"):
        np.testing.assert_array_equal(result[name], getattr(expected, name))
    assert np.isnan(result["foot_x"][~result["valid"]]).all()
    np.testing.assert_array_equal(result["desc_MAP-LIS"], expected.descriptors["MAP-LIS"])


def test_eval_reads_a_user_target_file(linkevo, genome_file, tmp_path):
    path, genomes = genome_file
    target = tmp_path / "flat.json"
    target.write_text(json.dumps({"step": [[-4, -1], [0, -1], [4, -1]], "lift": [[0, 2]]}))
    out = tmp_path / "r.npz"
    args = ("--fitness", "Fp2", "--target", str(target), "--out", str(out))
    done = linkevo("eval", str(path), *args, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert not np.allclose(np.load(out)["loss"], sim.evaluate(genomes, "Fp2").loss)
    d24 = linkevo("eval", str(path), "--target", "D24", "--out", str(out), cwd=tmp_path)
    assert d24.returncode == 0
    np.testing.assert_array_equal(
        np.load(out)["loss"], sim.evaluate(genomes, target=named_target("D24")).loss
    )


@pytest.mark.parametrize(
    ("content", "args", "message"),
    [
        (np.full((2, 56), np.nan), [], "row 0, gene 0"),
        (np.full((2, 55), 0.5), [], "shape (N, 56)"),
        (
            np.full((2, 56), 0.5),
            ["--target", "nowhere.json"],
            "is not allowed: D16, D24 or an existing .json target file",
        ),
        (np.zeros((0, 56)), [], "holds no genomes (shape (0, 56))"),
        (np.full((2, 56), 0.5), ["--angles", "1"], "--angles must be >= 3, got 1"),
        (np.full((2, 56), 0.5), ["--angles", "1000000000"], "--angles 1,000,000,000: 2 genome"),
        (b"", [], "cannot read 'g.npy' as a numeric .npy array: it is empty"),
        ("claims", [], "its header claims shape (1000000000, 56) of float64"),
    ],
)
def test_eval_refuses_bad_input_before_work(linkevo, tmp_path, content, args, message):
    if isinstance(content, bytes):
        (tmp_path / "g.npy").write_bytes(content)
    elif isinstance(content, str):  # a header that claims 10^9 rows over 2 rows of data
        np.save(tmp_path / "g.npy", np.full((2, 56), 0.5))
        raw = (tmp_path / "g.npy").read_bytes()
        header = raw[: raw.index(b"\n") + 1]
        claimed = header.replace(b"(2, 56)", b"(1000000000, 56)")
        claimed = claimed[: len(header) - 1].ljust(len(header) - 1) + b"\n"
        (tmp_path / "g.npy").write_bytes(claimed + raw[len(header) :])
    else:
        np.save(tmp_path / "g.npy", content)
    out = tmp_path / "r.npz"
    done = linkevo("eval", "g.npy", "--out", str(out), *args, cwd=tmp_path)
    assert done.returncode == 2
    assert message in done.stderr
    assert not out.exists()


def test_show_draws_png_and_gif_from_npy_and_json(linkevo, genome_file, tmp_path):
    path, genomes = genome_file
    png = tmp_path / "row.png"
    assert linkevo("show", f"{path}:5", "--out", str(png), cwd=tmp_path).returncode == 0
    with Image.open(png) as image:
        assert image.format == "PNG" and image.width > 300
    doc = tmp_path / "linkage.json"
    doc.write_text(json.dumps(to_document(genomes[5], "legacy")))
    gif = tmp_path / "turn.gif"
    done = linkevo("show", str(doc), "--out", str(gif), "--angles", "8", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    with Image.open(gif) as image:
        assert image.format == "GIF"
        assert image.n_frames == int(
            sim.evaluate(genomes[5:6], mode="legacy", n_angles=8).valid.sum()
        )
    bad = linkevo("show", f"{path}:999", "--out", str(png), cwd=tmp_path)
    assert bad.returncode == 2 and "999" in bad.stderr


@pytest.mark.parametrize(
    ("angles", "message"),
    [
        ("0", "--angles must be >= 3, got 0"),
        ("2", "--angles must be >= 3, got 2"),
        ("1000000000", "more than half of this machine's"),
    ],
)
def test_show_refuses_absurd_angle_counts(linkevo, genome_file, tmp_path, angles, message):
    out = tmp_path / "l.png"
    path, _ = genome_file
    done = linkevo("show", str(path), "--angles", angles, "--out", str(out), cwd=tmp_path)
    assert done.returncode == 2
    assert message in done.stderr and "Traceback" not in done.stderr
    assert not out.exists()
