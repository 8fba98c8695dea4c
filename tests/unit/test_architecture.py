"""The import rules of ARCHITECTURE.md: no import runs upwards through the layers.

Every ``import`` and ``from ... import`` of the package (at module level or inside a function)
is resolved to the part of the package it reaches, and checked against the table below.
"""

import ast
import re
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "selfas_graph"

#: part of the package -> the parts it may import from (besides itself); as in ARCHITECTURE.md
ALLOWED = {
    "kernels": set(),
    "parallel": set(),
    "_version": set(),
    "provenance": set(),
    "model": {"kernels", "parallel"},
    "io": {"model", "kernels", "_version", "provenance"},
    "lifecycle": {"io", "model", "kernels", "parallel", "_version", "provenance"},
    "analysis": {"model", "kernels"},
    "ensemble": {"analysis", "io", "lifecycle", "model", "kernels", "parallel", "_version", "provenance"},
    "grid": {"ensemble", "io", "parallel"},
    "studies": {"analysis", "ensemble", "io", "lifecycle", "model", "kernels", "parallel", "_version", "provenance"},
    "cli": {
        "analysis",
        "bench",
        "ensemble",
        "grid",
        "io",
        "lifecycle",
        "model",
        "kernels",
        "parallel",
        "_version",
        "provenance",
        "studies",
    },
    "bench": {
        "analysis",
        "cli",
        "ensemble",
        "grid",
        "io",
        "lifecycle",
        "model",
        "kernels",
        "parallel",
        "_version",
        "provenance",
        "studies",
        "__init__",
    },
    "__init__": {"analysis", "ensemble", "io", "model", "kernels", "parallel", "_version", "provenance"},
    "__main__": {"cli"},
}
#: the one upward import, inside functions: the schema walk of Parameters lives with the scenario files
EXCEPTIONS = {("model/params.py", "io")}


def _part(dotted):
    parts = dotted.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def _imports(path):
    """(line, dotted name) of every import of the package in ``path``, relative ones resolved."""
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    package = list(rel.parts[:-1])  # the package the module sits in (itself for an __init__.py)
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - (node.level - 1)]
                yield node.lineno, ".".join(base + ([node.module] if node.module else []))
            elif node.module and node.module.split(".")[0] == "selfas_graph":
                yield node.lineno, node.module
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "selfas_graph":
                    yield node.lineno, alias.name


def test_every_part_of_the_package_is_in_the_table():
    """A new package or top-level module gets its place in the layers (and in ARCHITECTURE.md)."""
    parts = {
        p.stem if p.is_file() else p.name
        for p in PACKAGE.iterdir()
        if (p.suffix == ".py" or (p / "__init__.py").exists())
    }
    assert parts <= set(ALLOWED), f"not in the import table: {sorted(parts - set(ALLOWED))}"


def test_every_module_of_the_core_has_its_row_in_architecture_md():
    """Each module of kernels/, model/ (terms/ included), io/ and the top level is named in
    ARCHITECTURE.md, where a maintainer looks for what it owns."""
    text = (PACKAGE.parent / "ARCHITECTURE.md").read_text(encoding="utf-8")
    modules = [
        p.relative_to(PACKAGE).as_posix()
        for tree in ("kernels", "model", "io", ".")
        for p in (PACKAGE / tree).glob("**/*.py" if tree == "model" else "*.py")
        if p.name != "__init__.py"
    ]
    assert len(modules) > 60
    missing = [m for m in modules if f"{m}" not in text]
    assert not missing, f"modules not named in ARCHITECTURE.md: {missing}"


def test_no_import_runs_upwards():
    bad = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        me = rel.split("/")[0].removesuffix(".py")
        for line, target in _imports(path):
            to = _part(target)
            if to == me or to in ALLOWED[me] or (rel, to) in EXCEPTIONS:
                continue
            bad.append(f"selfas_graph/{rel}:{line} imports {target}")
    assert not bad, "imports against the layers (ARCHITECTURE.md, 'Import rules'):\n" + "\n".join(bad)


def test_the_check_sees_relative_imports():
    """Not vacuous: relative imports resolve to full names, also from a subpackage (model/terms/)."""
    targets = {t for _, t in _imports(PACKAGE / "model" / "simulation.py")}
    assert "selfas_graph.model.terms" in targets and "selfas_graph.parallel" in targets
    targets = {t for _, t in _imports(PACKAGE / "model" / "terms" / "forcefield.py")}
    assert {"selfas_graph.parallel", "selfas_graph.model.neighbours", "selfas_graph.model.terms.base"} <= targets


#: the longest a module of the model may grow (lines): one concept per module, read in one sitting
MODEL_MODULE_LINES = 400
#: model modules not yet held to it (none)
NOT_YET_SPLIT: set[str] = set()


def test_model_modules_stay_short():
    """No module of selfas_graph/model/ is over MODEL_MODULE_LINES lines (ARCHITECTURE.md)."""
    long = {
        p.name: n
        for p in sorted((PACKAGE / "model").rglob("*.py"))
        if p.name not in NOT_YET_SPLIT and (n := len(p.read_text(encoding="utf-8").splitlines())) > MODEL_MODULE_LINES
    }
    assert not long, f"model modules over {MODEL_MODULE_LINES} lines: {long}; split them by concept"


#: the longest any module of the package may grow (lines): one concept per module (ARCHITECTURE.md)
MODULE_LINES = 600
#: modules over MODULE_LINES not yet split, with their length when this list was written: known
#: debts of kernels/ (none now; model/ is held to MODEL_MODULE_LINES above); no module elsewhere may join them
KNOWN_LONG_MODULES: dict[str, int] = {}


def _long_modules(limit):
    """Modules of the package (path relative to it -> lines) over ``limit`` lines, the known debts aside."""
    return {
        rel: n
        for p in sorted(PACKAGE.rglob("*.py"))
        if (rel := p.relative_to(PACKAGE).as_posix()) not in KNOWN_LONG_MODULES
        and (n := len(p.read_text(encoding="utf-8").splitlines())) > limit
    }


def test_modules_stay_short():
    """No module of selfas_graph/ is over MODULE_LINES lines, but for the known debts of kernels/."""
    long = _long_modules(MODULE_LINES)
    assert not long, f"modules over {MODULE_LINES} lines: {long}; split them by concept, one concept a module"


def test_the_length_check_sees_long_modules():
    """Not vacuous: with a lower limit the check finds modules, and the known debts are real files."""
    assert _long_modules(300)
    assert all((PACKAGE / rel).is_file() for rel in KNOWN_LONG_MODULES)
    assert all(rel.split("/")[0] in ("kernels", "model") for rel in KNOWN_LONG_MODULES)


#: the modules of tests/ that the tests import as top-level names (pyproject.toml, known-first-party)
TEST_MODULES = {"tests", "reference", "conftest", "hostile", "runfiles"}


def _reaches_outside(rel, text):
    """Where the module ``rel`` with source ``text`` imports from tests/ or changes ``sys.path``."""
    bad = []
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.Attribute) and node.attr in ("insert", "append"):
            v = node.value
            if isinstance(v, ast.Attribute) and v.attr == "path" and getattr(v.value, "id", None) == "sys":
                bad.append(f"{rel}:{node.lineno} changes sys.path")
        names = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            names = [node.module]
        bad += [f"{rel}:{node.lineno} imports {n}" for n in names if n.split(".")[0] in TEST_MODULES]
    if re.search(r"sys\.path\.(insert|append)", text):  # also in code held in strings (child processes)
        bad.append(f"{rel}: names sys.path.insert or sys.path.append")
    return sorted(set(bad))


def test_the_package_stands_alone():
    """The package imports nothing from tests/ (its oracles, fixtures or hostile inputs) and puts no
    folder on ``sys.path``: every module, the tools in ``bench/`` included, is imported as part of
    the package, so it runs from an installed copy as from the checkout."""
    bad = []
    # the launchers in tools/ run the package's tools as installed, without path tricks either
    for path in sorted(PACKAGE.rglob("*.py")) + sorted((PACKAGE.parent / "tools").glob("*.py")):
        bad += _reaches_outside(path.relative_to(PACKAGE.parent).as_posix(), path.read_text(encoding="utf-8"))
    assert not bad, "the package and tools/ must not reach into tests/ or onto sys.path:\n" + "\n".join(bad)


def test_the_stand_alone_check_sees_each_way_out():
    """Not vacuous: each way a module could reach outside the package is found."""
    for text in (
        "import sys\nsys.path.insert(0, 'tools')",
        "import sys\nsys.path.append('x')",
        "import reference",
        "from conftest import x",
        "from hostile import y",
        "import tests.runfiles",
        "RUNNER = 'import sys; sys.path.insert(0, d)'",
    ):
        assert _reaches_outside("m.py", text), text
    assert not _reaches_outside("m.py", "from . import oracles\nimport selfas_graph.bench.peer")
