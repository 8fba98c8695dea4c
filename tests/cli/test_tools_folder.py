"""tools/: one launcher per tool of ``selfas_graph.bench``, each running ``selfas-graph bench NAME``."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

from selfas_graph.cli.bench import tools

ROOT = Path(__file__).resolve().parents[2]


def _launched(script: Path) -> str:
    """The tool a launcher runs: the second string of its ``main([...])`` call."""
    for node in ast.walk(ast.parse(script.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "main":
            return node.args[0].elts[1].value
    raise AssertionError(f"{script.name} calls no main([...])")


def test_every_tool_has_one_launcher():
    launched = {script.name: _launched(script) for script in sorted((ROOT / "tools").glob("*.py"))}
    assert sorted(launched.values()) == sorted(tools()), "tools/ and selfas_graph.bench name other tools"
    for script, name in launched.items():
        assert script in (f"{name}.py", f"bench_{name}.py"), f"tools/{script} runs {name}: name it after the tool"


@pytest.mark.parametrize("script", ["bench_step.py", "same_as_commit.py"])
def test_a_launcher_runs_its_tool(script, tmp_path):
    """Run from another folder, as a user would: the installed package, not the checkout's path."""
    out = subprocess.run(
        [sys.executable, str(ROOT / "tools" / script), "--help"], cwd=tmp_path, capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr
    assert f"selfas-graph bench {script.removeprefix('bench_').removesuffix('.py')}" in out.stdout
