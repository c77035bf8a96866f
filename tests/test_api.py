"""The Python API (swarmloc/api.py, issue 45): each function against the command or engine it
wraps, for the same seed; bad settings refused as the command refuses them."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pandas as pd
import pytest

import swarmloc
from swarmloc.config import ConfigError
from swarmloc.deploy.cli import main as cli
from swarmloc.deploy.lab.epuck.batch import run_batch
from swarmloc.deploy.lab.epuck.experiment import LEAD_COLUMNS, METRIC_COLUMNS
from swarmloc.deploy.lab.replay.mrclam import ReplayConfig, run_replay
from swarmloc.deploy.observe.batch_record import run_batch_recorded
from swarmloc.deploy.scenario import load_scenario


def test_import_swarmloc_loads_none_of_the_heavy_libraries():
    code = ("import sys, swarmloc; heavy = [m for m in ('numba', 'zenoh', 'cv2', 'pandas', 'matplotlib') "
            "if m in sys.modules]; print(heavy); swarmloc.batch; print('pandas' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split("\n")[:2] == ["[]", "False"]


def test_batch_rows_are_the_experiment_columns_and_equal_direct_runs():
    df = swarmloc.batch("ES1", seeds=range(3, 5), duration_s=300.0, grid={"agent.strategy": ["NC", "SSGIKF"]})
    assert isinstance(df, pd.DataFrame) and len(df) == 4
    assert list(df.columns) == [*LEAD_COLUMNS, "agent.strategy", *METRIC_COLUMNS]
    for row in df.itertuples(index=False):
        r = row._asdict()
        direct = run_batch(load_scenario("ES1", [f"agent.strategy={r['strategy']}", f"world.seed={r['seed']}",
                                                  "world.duration_s=300.0"]))
        assert r["round_trips_total"] == direct.metrics["round_trips_total"]
        assert r["lost_total"] == direct.lost_count.sum()
        assert r["departures"] == direct.departure_error_m.size
        assert r["on_path_fraction_mean"] == pytest.approx(direct.metrics["on_path_fraction_mean"], abs=1e-12)
    assert sorted(set(df["seed"])) == [3, 4] and df["round_trips_total"].sum() > 0


@pytest.mark.parametrize(("settings", "words"), [
    ({"stratgy": "NC"}, "did you mean 'strategy'"),
    ({"agent__stratgy": "NC"}, "did you mean 'strategy'"),
    ({"strategy": "SSGIKX"}, "did you mean 'SSGIKF'"),
    ({"agent.encounter_combine": "median"}, "encounter_combine"),
])
def test_bad_settings_are_refused_as_the_command_refuses_them(settings, words, capsys):
    with pytest.raises(ConfigError, match=words) as info:
        swarmloc.batch("ES1", **settings)
    key, value = next(iter(settings.items()))
    if key.replace("__", ".").count("."):  # a dotted key: the same message as --set's
        assert cli(["batch", "ES1", "--set", f'{key.replace("__", ".")}="{value}"']) == 2
        assert str(info.value) in capsys.readouterr().err


@pytest.mark.parametrize("seeds", [0, [1, 3], [], True])
def test_seeds_are_a_count_or_consecutive(seeds):
    with pytest.raises((ValueError, TypeError), match="seeds"):
        swarmloc.batch("ES1", seeds=seeds)


def test_experiment_returns_the_results_file_and_resumes(tmp_path):
    spec = tmp_path / "tiny.toml"
    spec.write_text(textwrap.dedent("""
        name = "tiny"
        replications = 2
        [[group]]
        name = "g"
        scenarios = ["ES1"]
        duration_s = 60.0
        [group.grid]
        "agent.strategy" = ["NC", "SSGIKF"]
    """))
    out = tmp_path / "rows.csv"
    df = swarmloc.experiment(spec, out=out, workers=1, progress=False)
    assert len(df) == 4 and out.exists()
    pd.testing.assert_frame_equal(df, swarmloc.read_results(out))
    before = out.read_bytes()
    again = swarmloc.experiment(spec, out=out, workers=1, progress=False)  # nothing left to run
    assert out.read_bytes() == before
    pd.testing.assert_frame_equal(df, again)


def test_read_recording_gives_the_batch_runs_true_poses(tmp_path):
    scenario = load_scenario("ES1", ["world.robots=4", "world.duration_s=5"])
    path = tmp_path / "run.mcap"
    result = run_batch_recorded(scenario, path)
    df = swarmloc.read_recording(path)
    assert set(df["robot"]) == {0, 1, 2, 3}
    last = df[df["tick"] == df["tick"].max()].sort_values("robot")
    np.testing.assert_array_equal(last[["x_m", "y_m", "theta_rad"]].to_numpy(), result.final_pose)
    assert df["est_x_m"].notna().any() and df.attrs["truncated"] is None


def test_replay_frame_equals_the_replay_result(synthetic):
    df = swarmloc.replay(synthetic, algorithm="ekf", cooperative=True, duration_s=20.0, every_s=0.0)
    result = run_replay(synthetic, ReplayConfig(algorithm="ekf", cooperative=True, duration_s=20.0))
    assert len(df) == result.estimates.shape[0] * result.estimates.shape[1]
    for k, rid in enumerate(result.robot_ids):
        mine = df[df["robot"] == rid]
        np.testing.assert_array_equal(mine["x_m"].to_numpy(), result.estimates[:, k, 0])
        np.testing.assert_array_equal(mine["error_m"].to_numpy(), result.position_error_m()[:, k])
    with pytest.raises(ConfigError, match="algorithm"):
        swarmloc.replay(synthetic, algorithm="ekff")


def test_report_writes_the_page_of_a_batch(tmp_path):
    results = tmp_path / "r.csv"
    swarmloc.batch("ES1", seeds=2, duration_s=60.0, results=results)
    page = swarmloc.report(results, out=tmp_path / "page", title="api")
    text = page.read_text()
    assert page.exists() and "api" in text and "batch" in text


@pytest.mark.integration
def test_run_starts_processes_and_gives_the_batch_engines_metrics(tmp_path):
    df = swarmloc.run("ES1", robots=3, seed=2, duration_s=15.0, out=tmp_path)
    direct = run_batch(load_scenario("ES1", ["world.robots=3", "world.seed=2", "world.duration_s=15.0"]))
    assert len(df) == 1
    row = df.iloc[0]
    assert row["transport_ticks"] == 150 and row["rejected_messages"] == 0
    for key in ("round_trips_total", "robots_found_both"):
        assert row[key] == direct.metrics[key]
    assert row["on_path_fraction_mean"] == pytest.approx(direct.metrics["on_path_fraction_mean"], abs=1e-12)
    assert (tmp_path / row["folder"].split("/")[-1] / "results.json").exists()
