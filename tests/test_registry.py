"""Registries (swarmloc/registry.py): duplicates refused, unknown names answered with the closest
one, lazy "module:attribute" entries, plugins from SWARMLOC_PLUGINS and --plugin."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from swarmloc.registry import PLUGINS_ENV, Registry, resolve


def test_a_name_registers_once_and_unknown_names_suggest_the_closest():
    reg: Registry[int] = Registry("widget")
    reg.register("alpha", 1)
    reg.register("beta", 2)
    with pytest.raises(ValueError, match="widget 'alpha' is already registered"):
        reg.register("alpha", 3)
    assert reg.get("alpha") == 1 and reg.names() == ("alpha", "beta") and "beta" in reg
    with pytest.raises(ValueError, match=r"unknown widget 'alpah'; did you mean 'alpha'\?"):
        reg.get("alpah")
    with pytest.raises(ValueError, match="non-empty string"):
        reg.register("", 4)


def test_entries_given_as_paths_are_imported_when_loaded():
    reg: Registry[str] = Registry("thing")
    reg.register("join", "os.path:join")
    assert reg.load("join") is os.path.join
    assert resolve("swarmloc.registry:Registry.register") is Registry.register
    assert resolve(len) is len


def test_a_plugin_file_is_imported_in_the_process_and_its_children(tmp_path):
    plugin = tmp_path / "my_plugin.py"
    plugin.write_text("import os\nos.environ['SWARMLOC_TEST_PLUGIN_RAN'] = 'yes'\n")
    code = (f"import os; from swarmloc.registry import add_plugins; add_plugins([{str(plugin)!r}]);"
            f"print(os.environ['SWARMLOC_TEST_PLUGIN_RAN'], os.environ[{PLUGINS_ENV!r}])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=tmp_path, timeout=60).stdout.split()
    assert out == ["yes", str(plugin)]
    broken = tmp_path / "broken.py"
    broken.write_text("raise RuntimeError('boom')\n")
    done = subprocess.run([sys.executable, "-c", "from swarmloc.registry import load_plugins; load_plugins()"],
                          capture_output=True, text=True, check=False, timeout=60,
                          env={**os.environ, PLUGINS_ENV: str(broken)})
    assert done.returncode != 0 and "broken.py" in done.stderr and "boom" in done.stderr


def test_one_signature_a_check_at_registration_and_clashes_naming_both_places():
    from dataclasses import dataclass

    @dataclass(frozen=True)
    class Entry:
        name: str
        size: int

    def check(name, entry):
        if entry.size < 0:
            raise ValueError(f"size: must be >= 0, got {entry.size}")

    reg: Registry[Entry] = Registry("gadget", check)
    first = reg.register(Entry("a", 1))  # the name from the entry
    assert reg.get("a") is first and reg.register("b", Entry("b", 2)).size == 2  # or given
    assert reg.origin("a").startswith(__file__)
    with pytest.raises(ValueError, match=r"gadget 'c' \(registered at .*test_registry.py:\d+\): size: must be >= 0"):
        reg.register(Entry("c", -1))
    assert "c" not in reg
    with pytest.raises(ValueError, match=r"already registered \(at .*test_registry.py:\d+\); registered again at "
                                         r".*test_registry.py:\d+"):
        reg.register(Entry("a", 3))
    with pytest.raises(ValueError, match="needs an entry with a 'name'"):
        reg.register(42)
    # an unknown name may be a plugin's: the message says how to load one
    with pytest.raises(ValueError, match=r"unknown gadget 'zz'.*did you forget --plugin"):
        reg.get("zz")


def test_a_strategy_the_kernels_cannot_run_is_refused_when_registered():
    from swarmloc.agents.epuck.social_odometry import STRATEGIES, Strategy

    with pytest.raises(ValueError, match=r"gain: 'ci' is not one the compiled brain implements \(valid: 'none', "
                                         r"'kalman', 'fermi' or a fusion rule registered before the strategy"):
        STRATEGIES.register(Strategy("MINE_CI", communicates=True, double=False, gain="ci"))
    with pytest.raises(ValueError, match="needs a gain"):
        STRATEGIES.register(Strategy("MINE_NONE", communicates=True, double=False, gain="none"))
    assert "MINE_CI" not in STRATEGIES and "MINE_NONE" not in STRATEGIES
