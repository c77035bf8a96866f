"""The kernels compile once per machine, before any piece waits on another (deploy/warm.py).

A newcomer's first ``swarmloc run`` used to fail: on a cold numba cache the world and ten agents
compiled the same kernels at once, for longer than the join timeout. These tests start from an
empty cache folder, as a new machine has, and run the real command:

- ``pip install .`` (not editable) into a fresh virtual environment, then, on an empty cache in
  the user's cache folder and from another working directory, two ``swarmloc warm`` and a
  ``swarmloc run`` (router, world, 10 agents) at once: one process compiles, none twice, no
  piece of the run does, and the run completes; a second run of the same seed adds nothing to the
  cache and gives the same metrics (what :func:`exercise` compiles covers what a run calls), and
  no kernel is cached beside the installed sources. One test, so that the suite compiles the
  kernels from nothing once, not twice (about a minute each on two cores).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from processes import run_swarmloc

from swarmloc.deploy.warm import COMPILING_MESSAGE, fingerprint, is_warm, kernel_sources, stamp_path
from swarmloc.kernel_cache import default_dir

REPO = Path(__file__).resolve().parents[1]


def _cache_files(cache: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(cache)): (p.stat().st_size, p.stat().st_mtime_ns)
            for p in cache.rglob("*") if p.is_file() and not p.name.endswith(".lock")}


def test_the_stamp_names_every_kernel_source_and_a_changed_source_makes_it_stale(tmp_path, monkeypatch):
    names = {p.name for p in kernel_sources()}
    assert {"kernels.py", "agent_tick.py", "wire.py", "social_codec.py", "batch.py"} <= names
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert not is_warm(tmp_path)
    stamp_path(tmp_path).write_text(fingerprint())
    assert is_warm(tmp_path)
    stale = json.loads(fingerprint())
    stale["sources"][0][1] -= 1  # numba would see another modification time and recompile
    stamp_path(tmp_path).write_text(json.dumps(stale, indent=1))
    assert not is_warm(tmp_path)


def test_each_install_keeps_its_own_stamp_in_a_shared_cache_folder(tmp_path, monkeypatch):
    # Two checkouts sharing ~/.cache/swarmloc/numba: numba keys entries by source path, so each
    # install's stamp must be its own, or each takes the other's for stale and recompiles.
    from swarmloc.deploy import warm

    here = stamp_path(tmp_path)
    here.write_text(fingerprint())
    monkeypatch.setattr(warm, "_package_dirs", lambda: [tmp_path / "another-checkout"])
    assert stamp_path(tmp_path) != here
    assert not is_warm(tmp_path)  # the other install finds no stamp of its own


def test_a_stale_stamp_forgets_entries_numba_would_keep_for_a_changed_callee(tmp_path):
    # numba checks a cached function against its own file only: ``outer`` in one file keeps the
    # machine code of ``inner`` from another file after ``inner`` changed. forget_cached (called
    # by ensure_compiled on a stale stamp) deletes the entries so the next import recompiles.
    from swarmloc.deploy.warm import forget_cached

    code, cache = tmp_path / "code", tmp_path / "cache"
    code.mkdir()
    (code / "callee.py").write_text("from numba import njit\n\n@njit(cache=True)\n"
                                    "def inner():\n    return 1\n")
    (code / "caller.py").write_text("from numba import njit\nfrom callee import inner\n\n"
                                    "@njit(cache=True)\ndef outer():\n    return inner() * 10\n")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "PYTHONPATH": str(code)}

    def outer() -> int:
        out = subprocess.run([sys.executable, "-c", "import caller; print(caller.outer())"],
                             check=False, env=env, cwd=code, capture_output=True, text=True,
                             timeout=120)
        assert out.returncode == 0, out.stderr
        return int(out.stdout)

    assert outer() == 10
    (code / "callee.py").write_text((code / "callee.py").read_text().replace("return 1", "return 22"))
    stale = outer()  # numba 0.68 alone gives 10 here: the old inner, silently
    assert forget_cached(cache, [code / "caller.py", code / "callee.py"]) >= 2
    assert outer() == 220, f"before forget_cached: {stale}"


def test_the_cache_is_per_user_and_falls_back_when_home_is_not_writable(tmp_path, monkeypatch):
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert default_dir() == tmp_path / "home" / ".cache" / "swarmloc" / "numba"
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert default_dir() == tmp_path / "xdg" / "swarmloc" / "numba"
    blocker = tmp_path / "file"
    blocker.write_text("")  # a cache home that is a file cannot hold folders
    monkeypatch.setenv("XDG_CACHE_HOME", str(blocker))
    fallback = default_dir()
    assert fallback.parts[-2:] == (f"swarmloc-{os.getuid()}", "numba") and blocker not in fallback.parents


@pytest.mark.integration
def test_a_family_without_kernels_runs_from_an_empty_cache_without_compiling_them(tmp_path):
    # Issue 48: a laser run compiled the e-puck kernels it never calls (79 of its first 91 s).
    # Family.compiled_kernels says which families run them; the launcher, the world and the
    # agents (told the family by the launcher) skip compiling for the others.
    cache = tmp_path / "numba"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    out = tmp_path / "runs"
    done = run_swarmloc(["run", "laser-collab-three-rooms", "--set", "world.steps=30", "--out", str(out),
                         "--run", "laser"], env=env, cwd=tmp_path, timeout_s=300)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "compiling kernels" not in done.stderr
    for log in (out / "laser" / "logs").iterdir():
        assert "compiling kernels" not in log.read_text(), log
    assert not _cache_files(cache) and not is_warm(cache)
    assert json.loads((out / "laser" / "results.json").read_text())["metrics"]["steps"] == 30


@pytest.mark.integration
def test_a_non_editable_install_warms_once_and_runs_from_another_folder(tmp_path):
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120)
    python = str(venv / "bin" / "python")
    pip = subprocess.run([python, "-m", "pip", "install", "--quiet", "--disable-pip-version-check",
                          str(REPO)], capture_output=True, text=True, timeout=900, check=False)
    assert pip.returncode == 0, pip.stderr[-3000:]
    site = subprocess.run([python, "-c", "import swarmloc, pathlib; print(pathlib.Path(swarmloc.__file__).parent)"],
                          capture_output=True, text=True, check=True, cwd=tmp_path, timeout=60).stdout.strip()
    assert str(venv) in site and str(REPO) not in site, "swarmloc imported from the checkout, not the install"

    home = tmp_path / "home"
    home.mkdir()
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "XDG_CACHE_HOME", "PYTHONPATH")}
    env["HOME"] = str(home)
    # Three pieces starting at once on a cold machine, a run among them: one compiles, the
    # others wait for it, and no piece of the run compiles.
    runs = elsewhere / "runs"
    commands = [["warm"], ["warm"], ["run", "--duration-s", "60", "--run", "cold", "--out", str(runs)]]
    procs = [subprocess.Popen([python, "-m", "swarmloc", *c], cwd=elsewhere, env=env, text=True,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                              start_new_session=True)
             for c in commands]
    try:
        outputs = [p.communicate(timeout=420)[0] for p in procs]
    finally:
        for p in procs:
            if p.poll() is None:
                os.killpg(p.pid, 9)
                p.wait()
    assert [p.returncode for p in procs] == [0, 0, 0], outputs
    assert sum(o.count(COMPILING_MESSAGE) for o in outputs) == 1, outputs
    assert "round trips" in outputs[2]
    for log in (runs / "cold" / "logs").iterdir():  # the launcher waited or compiled; no piece had to
        assert "compiling kernels" not in log.read_text(), log
    cache = home / ".cache" / "swarmloc" / "numba"
    assert len(list(cache.glob("swarmloc-kernels-*.stamp"))) == 1, outputs  # the installed copy's
    assert not list(Path(site).rglob("*.nbi")), "kernels cached beside the installed sources"
    before = _cache_files(cache)
    assert sum(name.endswith(".nbi") for name in before) > 10

    run = run_swarmloc(["run", "--duration-s", "60", "--run", "warm", "--out", str(runs)], env=env, cwd=elsewhere,
                       timeout_s=300, python=python)
    assert run.returncode == 0, run.stderr[-3000:]
    assert "compiling kernels" not in run.stderr and "round trips" in run.stdout
    assert _cache_files(cache) == before, "a warm run compiled something the warm-up did not"
    cold = json.loads((runs / "cold" / "results.json").read_text())
    warm = json.loads((runs / "warm" / "results.json").read_text())
    assert warm["transport"]["ticks"] == 600 and warm["robots"] == 10 and cold["seed"] == warm["seed"] == 1
    assert cold["metrics"] == warm["metrics"] and warm["metrics"]["robots_found_both"] > 0  # the robots foraged
