"""Layers: nothing under ``agents/`` or ``world/`` (the pure models and their process shells)
imports ``swarmloc.deploy`` (launching, experiments, the command line), so that a model can be
used, tested and packaged without the tool around it (ARCHITECTURE.md, issue 48).

The imports that predated the rule were moved (KNOWN lists any still allowed: none); the test
fails on any import not listed, and on a listed one that is gone (so the list only shrinks)."""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

#: (file, module imported) still to move: none (issue 48 moved the laser registry and scoring,
#: the vision scenario, the replay evaluation and the any-family scenario below deploy/).
KNOWN: set[tuple[str, str]] = set()


def _deploy_imports(root: Path = REPO) -> set[tuple[str, str]]:
    found = set()
    for top in ("agents", "world"):
        for path in sorted((root / top).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
                if isinstance(node, ast.ImportFrom) and node.module:
                    names = [node.module]
                elif isinstance(node, ast.Import):
                    names = [a.name for a in node.names]
                else:
                    continue
                for name in names:
                    if name == "swarmloc.deploy" or name.startswith("swarmloc.deploy."):
                        found.add((path.relative_to(root).as_posix(), name))
    return found


def test_no_model_or_shell_imports_the_tool_around_it():
    found = _deploy_imports()
    assert found - KNOWN == set(), "new imports of swarmloc.deploy under agents/ or world/"
    assert KNOWN - found == set(), "these were moved: take them off KNOWN"


def test_the_check_sees_imports_inside_functions_and_plain_imports(tmp_path):
    # the imports being moved are inside functions (lazy): the walk must see those too
    (tmp_path / "agents" / "x").mkdir(parents=True)
    (tmp_path / "world").mkdir()
    (tmp_path / "agents" / "x" / "a.py").write_text(
        "import swarmloc.protocol\ndef f():\n    from swarmloc.deploy.lab import report\n")
    (tmp_path / "world" / "w.py").write_text("import swarmloc.deploy\nimport swarmloc.deployment_notes\n")
    assert _deploy_imports(tmp_path) == {("agents/x/a.py", "swarmloc.deploy.lab"), ("world/w.py", "swarmloc.deploy")}
