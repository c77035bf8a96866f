"""The documentation (issue 45): the site builds strictly, the README routes a newcomer, the
notebooks run and compute what they say, and the package is typed and buildable as a release."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent


def _tool(name: str) -> str:
    """A console script of this environment (CI installs them with the test extra)."""
    path = BIN / name
    if not path.exists():
        pytest.fail(f"{name} is not installed: pip install -e '.[test]'")
    return str(path)


def _mkdocs_build(config: Path, site: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    return subprocess.run([_tool("mkdocs"), "build", "--strict", "--config-file", str(config), "--site-dir",
                           str(site)], capture_output=True, text=True, env=env, timeout=180, check=False)


# ---- the site -------------------------------------------------------------------------------

def test_the_site_builds_strictly_with_every_api_function(tmp_path):
    done = _mkdocs_build(ROOT / "mkdocs.yml", tmp_path / "site")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "WARNING" not in done.stdout + done.stderr
    api = (tmp_path / "site" / "api" / "index.html").read_text()
    for name in ("batch", "experiment", "run", "replay", "read_recording", "read_results", "report"):
        assert f'id="swarmloc.api.{name}"' in api, name
    for page in ("families/epuck", "families/laser", "families/vision", "families/real-data", "design",
                 "figures", "experiments", "mrclam", "social-odometry-000"):
        assert (tmp_path / "site" / page / "index.html").exists(), page


def test_a_broken_link_fails_the_strict_build(tmp_path):
    """The check above can fail: the same site with one dead link does not build."""
    copy = tmp_path / "repo"
    shutil.copytree(ROOT / "docs", copy / "docs")
    shutil.copy(ROOT / "mkdocs.yml", copy / "mkdocs.yml")
    shutil.copytree(ROOT / "src", copy / "src", ignore=shutil.ignore_patterns("__pycache__"))
    page = copy / "docs" / "families" / "vision.md"
    page.write_text(page.read_text() + "\nSee [a page that is not there](nowhere.md).\n")
    done = _mkdocs_build(copy / "mkdocs.yml", tmp_path / "site")
    assert done.returncode != 0 and "nowhere.md" in done.stdout + done.stderr


# ---- the README -----------------------------------------------------------------------------

README = (ROOT / "README.md").read_text()


def test_readme_is_short_and_starts_with_the_two_commands():
    assert len(README.splitlines()) < 150
    blocks = re.findall(r"```bash\n(.*?)```", README, re.DOTALL)
    assert blocks[:2] == ["python3 -m venv .venv && . .venv/bin/activate && pip install -e '.[test]' && swarmloc run\n",
                          "pytest\n"]
    for family in ("docs/families/epuck.md", "docs/families/laser.md", "docs/families/vision.md",
                   "docs/families/real-data.md"):
        assert f"]({family})" in README
    assert 'swarmloc.batch("ES1", seeds=10, grid={"agent.strategy": ["NC", "SSGIKF"]})' in README


def test_readme_links_point_at_files_that_exist():
    targets = re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", README)
    local = [t for t in targets if not t.startswith(("http://", "https://"))]
    assert len(local) > 15
    missing = [t for t in local if not (ROOT / t).exists()]
    assert missing == []


#: Every command the README showed before issue 45 moved its material into docs/: each must
#: still be written somewhere a reader finds it.
FORMER_README_COMMANDS = [
    "swarmloc scenarios", "swarmloc run ES1 --strategy NC --seed 3",
    "swarmloc run ES1 --set agent.beta=0.001 --strategy SSGIFF", "swarmloc run --realtime --duration-s 60",
    "swarmloc batch ES1 --strategy SSGIKF", "swarmloc experiment --list", "swarmloc experiment es1-preview",
    "swarmloc experiment social-odometry-000 --dry-run",
    "swarmloc report results/es1-preview.csv --reasons docs/es1-preview/reasons.toml",
    "swarmloc experiment social-odometry-000 --executor dask --scheduler tcp://HEAD:8786",
    "swarmloc run laser-collab-three-rooms", "swarmloc run laser-kidnap-office --algorithm amcl",
    "swarmloc experiment laser-table3", "swarmloc report results/laser-table3.csv results/laser-kidnap.csv",
    "swarmloc run vision-exp3", "swarmloc experiment vision", "swarmloc report results/vision.csv --out docs/vision",
    "swarmloc run mrclam6-ekf-coop --duration-s 60", "swarmloc experiment mrclam6",
    "swarmloc report results/mrclam6.csv --out docs/mrclam",
    "swarmloc mrclam ../shared/data/mrclam/MRCLAM_Dataset6 --algorithm ekf --cooperative",
    "swarmloc status -e tcp/ROUTER:7447", "swarmloc run --view", "swarmloc view --run lab1 -e tcp/ROUTER:7447",
    "swarmloc run ES1 --record es1.mcap --record-messages", "swarmloc batch ES1 --record es1-batch.mcap",
    "swarmloc record --run lab1 lab1.mcap", "swarmloc run laser-collab-three-rooms --view --particles 64",
    "swarmloc view es1.mcap", "swarmloc replay es1.mcap --speed 2",
    "swarmloc --plugin examples/cem_localizer.py check laser-collab-three-rooms --algorithm cem",
    "swarmloc --plugin examples/cem_localizer.py experiment examples/cem-vs-baselines.toml",
    "swarmloc router -l tcp/0.0.0.0:7447", "swarmloc world ES1 -e tcp/ROUTER:7447 --run lab1 --out results/",
    "swarmloc agent --robot 0 -e tcp/ROUTER:7447 --run lab1", "swarmloc agents --robots 0-49 -e tcp/ROUTER:7447 --run lab1",
    "python benchmarks/bench_first_run.py", "SWARMLOC_SCREENSHOTS=docs/images pytest",
]


def test_every_former_readme_command_is_still_in_the_docs():
    text = README + "".join(p.read_text() for p in (ROOT / "docs").rglob("*.md"))
    assert [c for c in FORMER_README_COMMANDS if c not in text] == []


# ---- the notebooks ---------------------------------------------------------------------------

NOTEBOOKS = ROOT / "examples" / "notebooks"


def _execute(name: str, tmp_path: Path) -> dict:
    """Run ``examples/notebooks/NAME`` in a copy of its folder's layout under ``tmp_path`` (the
    notebook beside a copy of the example plugin, as in the repository) and return the JSON its
    last cell prints after ``RESULT``."""
    import json

    import nbformat
    from nbclient import NotebookClient

    (tmp_path / "notebooks").mkdir()
    shutil.copy(ROOT / "examples" / "cem_localizer.py", tmp_path / "cem_localizer.py")
    nb = nbformat.read(NOTEBOOKS / name, as_version=4)
    NotebookClient(nb, timeout=240, kernel_name="python3",
                   resources={"metadata": {"path": str(tmp_path / "notebooks")}}).execute()
    last = nb.cells[-1]
    text = "".join(o.get("text", "") for o in last.outputs if o.get("output_type") == "stream")
    lines = [line for line in text.splitlines() if line.startswith("RESULT ")]
    assert len(lines) == 1, text
    return json.loads(lines[0][len("RESULT "):])


@pytest.mark.parametrize("name", ["quickstart.ipynb", "real-data.ipynb", "add-a-localizer.ipynb"])
def test_notebooks_are_stored_without_outputs(name):
    import nbformat

    nb = nbformat.read(NOTEBOOKS / name, as_version=4)
    nbformat.validate(nb)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert code and all(c.outputs == [] and c.execution_count is None for c in code)


def test_quickstart_notebook_gives_the_batch_engines_round_trips(tmp_path):
    from swarmloc.deploy.lab.epuck.batch import run_batch
    from swarmloc.deploy.scenario import load_scenario

    result = _execute("quickstart.ipynb", tmp_path)
    assert result["seeds"] == [1, 2, 3] and result["duration_s"] == 300.0
    for strategy in ("NC", "SSGIKF"):  # seed 1 of each, run directly
        direct = run_batch(load_scenario("ES1", [f"agent.strategy={strategy}", "world.seed=1",
                                                 "world.duration_s=300.0"]))
        assert result["round_trips"][strategy][0] == direct.metrics["round_trips_total"]
    assert result["recorded_robots"] == 10 and result["recorded_last_t_s"] == 60.0


def test_real_data_notebook_gives_the_replays_errors(tmp_path, monkeypatch):
    import numpy as np
    from mrclam_synthetic import SYNTH_CAMERA, SYNTH_MOTION

    import swarmloc
    from swarmloc.world.replay.mrclam import SyntheticConfig, synthesize, write_dataset

    monkeypatch.setenv("SWARMLOC_MRCLAM", "synthetic")  # CI has no MRCLAM data
    result = _execute("real-data.ipynb", tmp_path)
    assert result["source"] == "synthetic" and result["rows"] == 3 * 40
    folder = write_dataset(synthesize(SyntheticConfig(n_robots=3, n_landmarks=8, duration_s=40.0),
                                      np.random.default_rng(11)), tmp_path / "data")
    for mode, cooperative in (("alone", False), ("cooperative", True)):
        df = swarmloc.replay(folder, algorithm="ekf", cooperative=cooperative, duration_s=40.0,
                             motion=SYNTH_MOTION, camera=SYNTH_CAMERA, calibration="none")
        expected = df.groupby("robot")["error_m"].median()
        assert result["median_error_m"][mode] == {str(r): float(v) for r, v in expected.items()}
        assert max(expected) < 0.1


def test_add_a_localizer_notebook_checks_and_measures_the_plugin(tmp_path):
    result = _execute("add-a-localizer.ipynb", tmp_path)
    assert result["check_passed"] == ["types", "determinism", "pure", "bad input"]
    assert result["algorithms"] == ["cem", "ssga"] and len(result["final_error_m"]) == 4
    # seeds 1-2 on the three-rooms floor: every robot settles, within 5 cm (measured 3.5-3.9 cm)
    assert all(n == 3 for n in result["settled_robots"].values())
    assert all(e < 0.05 for e in result["final_error_m"].values())


# ---- packaging as a release would be --------------------------------------------------------

def test_the_public_api_type_checks():
    done = subprocess.run([sys.executable, "-m", "mypy", "src/swarmloc/api.py"], cwd=ROOT, capture_output=True,
                          text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "Success: no issues found in 1 source file" in done.stdout


def test_mypy_would_catch_a_wrong_return_type(tmp_path):
    """The check above can fail: a copy of the API that returns the wrong type is refused."""
    bad = tmp_path / "api_bad.py"
    bad.write_text((ROOT / "src" / "swarmloc" / "api.py").read_text().replace(
        'return Path(out) / "README.md"', 'return str(Path(out) / "README.md")'))
    done = subprocess.run([sys.executable, "-m", "mypy", "--config-file", str(ROOT / "pyproject.toml"), str(bad)],
                          cwd=ROOT, capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 1 and "Incompatible return value type" in done.stdout, done.stdout


def test_sdist_and_wheel_build_pass_twine_check_and_the_wheel_runs_alone(tmp_path):
    import zipfile

    done = subprocess.run([sys.executable, "-m", "build", "--outdir", str(tmp_path), str(ROOT)],
                          capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    wheels, sdists = list(tmp_path.glob("*.whl")), list(tmp_path.glob("*.tar.gz"))
    assert len(wheels) == 1 and len(sdists) == 1
    names = zipfile.ZipFile(wheels[0]).namelist()
    assert "swarmloc/py.typed" in names and "swarmloc/api.py" in names
    check = subprocess.run([_tool("twine"), "check", "--strict", *map(str, wheels + sdists)],
                           capture_output=True, text=True, timeout=120, check=False)
    assert check.returncode == 0 and check.stdout.count("PASSED") == 2, check.stdout + check.stderr
    _wheel_runs_outside_the_checkout(wheels[0], tmp_path)


def _wheel_runs_outside_the_checkout(wheel: Path, tmp_path: Path) -> None:
    """The wheel alone (installed into a folder of its own, the dependencies from this
    environment) holds every layer and data file: its scenarios load and a replay runs."""
    target = tmp_path / "installed"
    done = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--target", str(target),
                           str(wheel)], capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr
    code = textwrap.dedent("""
        import numpy as np, swarmloc, swarmloc.api
        from swarmloc.deploy.scenario import load_any
        from swarmloc.world.replay.mrclam import SyntheticConfig, synthesize
        assert swarmloc.__file__.startswith(TARGET) and swarmloc.api.__file__.startswith(TARGET)
        import swarmloc.deploy, swarmloc.world
        assert swarmloc.deploy.__file__.startswith(TARGET) and swarmloc.world.__file__.startswith(TARGET)
        for name in ("ES1", "laser-collab-three-rooms", "vision-exp3", "mrclam6-ekf-coop"):
            load_any(name)
        data = synthesize(SyntheticConfig(n_robots=2, n_landmarks=6, duration_s=10.0), np.random.default_rng(1))
        df = swarmloc.replay(data, algorithm="ekf", cooperative=True)
        print(sorted(set(df["robot"])), len(df))
    """).replace("TARGET", repr(str(target)))
    env = {**os.environ, "PYTHONPATH": str(target)}
    run = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=300, check=False)
    assert run.returncode == 0, run.stderr[-3000:]
    assert run.stdout.split("\n")[0] == "[1, 2] 20"
    assert (target / "swarmloc" / "py.typed").exists()


def test_changelog_keeps_an_unreleased_section():
    text = (ROOT / "CHANGELOG.md").read_text()
    assert "keepachangelog.com" in text
    unreleased = text.split("## [Unreleased]", 1)[1].split("\n## [", 1)[0]
    assert "### Added" in unreleased and "swarmloc.batch" in unreleased


def test_the_api_pages_column_table_is_the_experiment_engines():
    import importlib

    rows = {}
    for line in (ROOT / "docs" / "api.md").read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 3 and cells[1].startswith("`experiment`"):
            rows[cells[0].split()[0]] = [re.findall(r"`([^`]+)`", c) for c in cells[1:]]
    assert sorted(rows) == ["e-puck", "laser", "replay", "vision"]
    for family, folder in (("e-puck", "epuck"), ("laser", "laser"), ("vision", "vision"), ("replay", "replay")):
        module = importlib.import_module(f"swarmloc.deploy.lab.{folder}.experiment")
        assert rows[family] == [list(module.LEAD_COLUMNS), list(module.METRIC_COLUMNS)], family
