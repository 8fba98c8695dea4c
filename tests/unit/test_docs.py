"""The documentation cannot drift from the code.

- docs/scenarios.md is exactly what selfas_graph/bench/scenario_docs.py renders from the schema;
- every scenario key that a page in docs/ names (``section.key`` in backticks) exists in the
  schema of :mod:`selfas_graph.model.params`;
- every ``tests/<file>.py::<name>`` reference names an existing test function, and every
  ``selfas_graph/<module>.py::<name>`` reference an existing function, class or constant.
"""

import ast
import dataclasses
import re
import typing
from pathlib import Path

import pytest

from selfas_graph.io.scenario import scenario_from_text
from selfas_graph.model import params as P

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
DOC_PAGES = sorted(DOCS.glob("*.md"))
REGENERATE = "run `selfas-graph bench scenario_docs` to regenerate docs/scenarios.md"


@pytest.fixture(scope="module")
def tool():
    """The generator of docs/scenarios.md, selfas_graph/bench/scenario_docs.py."""
    from selfas_graph.bench import scenario_docs

    return scenario_docs


def _backticked(text):
    """Contents of the inline code spans of a markdown text (fenced blocks left out)."""
    text = re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)
    return re.findall(r"`([^`\n]+)`", text)


# ----------------------------------------------------------------------------- scenarios.md


def test_scenarios_md_is_up_to_date(tool):
    """docs/scenarios.md equals render(): the reference lists the schema as it is now."""
    path = DOCS / "scenarios.md"
    assert path.exists(), f"docs/scenarios.md is missing; {REGENERATE}"
    assert path.read_text(encoding="utf-8") == tool.render(), f"docs/scenarios.md is out of date; {REGENERATE}"


def test_check_flag_reports_a_stale_file(tool, tmp_path, monkeypatch, capsys):
    """``--check`` exits 0 on an up-to-date file and 1, with the command to run, on a stale one."""
    out = tmp_path / "docs" / "scenarios.md"
    monkeypatch.setattr(tool, "ROOT", tmp_path)
    monkeypatch.setattr(tool, "OUTPUT", out)
    assert tool.main([]) == 2 and not out.exists()  # no checkout there (an installed package): nothing written
    assert "not from a source checkout" in capsys.readouterr().err
    (tmp_path / "pyproject.toml").write_text("")
    assert tool.main(["--check"]) == 1  # missing
    assert tool.main([]) == 0 and out.read_text(encoding="utf-8") == tool.render()
    assert tool.main(["--check"]) == 0
    out.write_text(tool.render() + "\nhand edit\n", encoding="utf-8")
    capsys.readouterr()
    assert tool.main(["--check"]) == 1
    assert "selfas-graph bench scenario_docs" in capsys.readouterr().err


def test_example_scenario_in_scenarios_md_loads():
    """The example at the top of docs/scenarios.md is a valid scenario."""
    text = (DOCS / "scenarios.md").read_text(encoding="utf-8")
    blocks = re.findall(r"^```toml\n(.*?)^```", text, flags=re.S | re.M)
    assert blocks, "docs/scenarios.md has no ```toml example"
    for block in blocks:
        scenario_from_text(block)


# ----------------------------------------------------------------------------- scenario keys


def _schema_paths(cls=P.Parameters, prefix=""):
    """Every table and key path of the scenario schema, walking the parameter dataclasses."""
    out = set()
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        path = f"{prefix}{f.name}"
        out.add(path)
        tp = hints[f.name]
        if typing.get_origin(tp) is typing.Union:
            tp = next(a for a in typing.get_args(tp) if a is not type(None))
        if dataclasses.is_dataclass(tp):
            out |= _schema_paths(tp, path + ".")
    return out


SCHEMA = _schema_paths()
SECTIONS = {f.name for f in dataclasses.fields(P.Parameters)}
KEY_LIKE = re.compile(r"^[A-Za-z_]\w*(\.[A-Za-z_]\w*)+$")


def _key_mentions(text):
    """Backticked strings that look like scenario keys: ``forces.yukawa.tolerance``,
    ``[forces.yukawa]``, ``--set forces.yukawa=false``; the first part must be a section."""
    found = []
    for span in _backticked(text):
        candidate = span.strip()
        if candidate.startswith("--set "):
            candidate = candidate[len("--set ") :]
        candidate = candidate.split("=")[0].strip().strip("[]")
        if KEY_LIKE.match(candidate) and candidate.split(".")[0] in SECTIONS:
            found.append(candidate)
    return found


def test_model_md_names_scenario_keys():
    """The check below is not vacuous: docs/model.md names scenario keys in backticks."""
    assert len(_key_mentions((DOCS / "model.md").read_text(encoding="utf-8"))) > 20


@pytest.mark.parametrize("page", DOC_PAGES, ids=lambda p: p.name)
def test_every_key_named_in_the_docs_exists(page):
    """Every ``section.key`` in backticks in a docs page is a key or table of the scenario schema."""
    missing = sorted({k for k in _key_mentions(page.read_text(encoding="utf-8")) if k not in SCHEMA})
    assert not missing, f"docs/{page.name} names scenario keys that do not exist: {missing}"


# ----------------------------------------------------------------------------- code references


def _defined_names(path: Path):
    """Top-level functions, classes and assigned names of a module, and ``Class.method`` names."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            names.add(node.name)
        elif isinstance(node, ast.ClassDef):
            names.add(node.name)
            for item in node.body:
                if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    names.add(f"{node.name}.{item.name}")
        elif isinstance(node, ast.Assign):
            names |= {t.id for t in node.targets if isinstance(t, ast.Name)}
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    return names


def _test_functions(path: Path):
    """Names of the test functions of a test module (module level and in classes)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name.startswith("test"):
            names.add(node.name)
    return names


TEST_REF = re.compile(r"tests/([\w/]+\.py)::(\w+)")
CODE_REF = re.compile(r"(selfas_graph/[\w/]+\.py)::([\w.]+)")


def test_model_md_cites_tests():
    """The check below is not vacuous: docs/model.md cites tests as tests/<file>.py::<name>."""
    assert len(TEST_REF.findall((DOCS / "model.md").read_text(encoding="utf-8"))) > 50


@pytest.mark.parametrize("page", DOC_PAGES, ids=lambda p: p.name)
def test_every_cited_test_exists(page):
    """Every ``tests/<file>.py::<name>`` in a docs page names an existing test function."""
    bad = []
    cache = {}
    for file, name in TEST_REF.findall(page.read_text(encoding="utf-8")):
        path = ROOT / "tests" / file
        if not path.is_file():
            bad.append(f"tests/{file}::{name} (no such file)")
            continue
        if file not in cache:
            cache[file] = _test_functions(path)
        if name not in cache[file]:
            bad.append(f"tests/{file}::{name}")
    assert not bad, f"docs/{page.name} cites tests that do not exist: {sorted(set(bad))}"


@pytest.mark.parametrize("page", DOC_PAGES, ids=lambda p: p.name)
def test_every_cited_function_exists(page):
    """Every ``selfas_graph/<module>.py::<name>`` in a docs page names an existing definition."""
    bad = []
    for file, name in CODE_REF.findall(page.read_text(encoding="utf-8")):
        path = ROOT / file
        if not path.is_file():
            bad.append(f"{file}::{name} (no such file)")
        elif name.rstrip(".") not in _defined_names(path):
            bad.append(f"{file}::{name}")
    assert not bad, f"docs/{page.name} names code that does not exist: {sorted(set(bad))}"


#: ARCHITECTURE.md names code by its path in the package: `model/network.py::Network.update`
ARCH_REF = re.compile(r"`((?:[a-z_]+/)*[a-z_]+\.py)::([\w.]+)`")


def test_every_function_architecture_md_names_exists():
    """Every ``path.py::name`` of ARCHITECTURE.md (a path inside the package) names an existing
    definition, so that the guides to changing the code do not send a maintainer to code that moved."""
    refs = ARCH_REF.findall((ROOT / "ARCHITECTURE.md").read_text(encoding="utf-8"))
    assert len(refs) > 20  # not vacuous
    bad = []
    for file, name in refs:
        path = ROOT / "selfas_graph" / file
        if not path.is_file():
            bad.append(f"{file}::{name} (no such file)")
        elif name not in _defined_names(path):
            bad.append(f"{file}::{name}")
    assert not bad, f"ARCHITECTURE.md names code that does not exist: {sorted(set(bad))}"


# ----------------------------------------------------------------------------- citations of docs/model.md

#: the form the code cites docs/model.md in: the page's path, a space and a heading of the page in
#: single quotes (double quotes if it has an apostrophe), without its number or cut at its colon
#: (``'Circuit'``, ``'Term 9'``); further
#: headings may follow, separated by ``, `` or `` or ``/`` and ``
_NAME = r"""(?:'[^'\n]+'|"[^"\n]+")"""  # in single quotes, or in double quotes when it has an apostrophe
MODEL_CITE = re.compile(rf"docs/model\.md\s+({_NAME}(?:(?:,\s*|\s+or\s+|\s+and\s+){_NAME})*)")
CITING_TREES = ("selfas_graph", "tests", "scenarios")
_QUOTED = re.compile("'([^'\\n]+)'|\"([^\"\\n]+)\"")
OLD_NAME = "MODEL" + ".md"  # the project's model text, which users do not have


def _model_md_headings(page="model.md"):
    """Headings of docs/model.md (or another page of docs/) without their numbers, and the part of each
    before a colon."""
    names = set()
    for line in (DOCS / page).read_text(encoding="utf-8").splitlines():
        if line.startswith("#"):
            title = re.sub(r"^\d+[a-z]?(\.\d+)?\.?\s+", "", line.lstrip("#").strip())
            names |= {title, title.split(":")[0].strip()}
    return names


def _joined(path):
    """The text of ``path`` with a citation that runs over lines made one line: adjacent string literals
    (a heading cut between two f-strings of a message) and comment lines continued are joined, spaces
    collapsed."""
    text = re.sub(r"""["']\s*\n\s*[rfbu]*["']""", "", path.read_text(encoding="utf-8"))
    text = text.replace("\\'", "'").replace('\\"', '"')  # escaped quotes inside a literal
    text = re.sub(r"\n\s*#\s*", " ", text)
    return re.sub(r"\s+", " ", text)


def _citing_files():
    return sorted(
        p for tree in CITING_TREES for p in (ROOT / tree).rglob("*") if p.suffix in (".py", ".toml") and p.is_file()
    )


def test_code_cites_docs_model_md():
    """The check below is not vacuous: the code cites docs/model.md sections by name."""
    count = sum(len(MODEL_CITE.findall(p.read_text(encoding="utf-8"))) for p in _citing_files())
    assert count > 50


def test_every_docs_model_md_section_cited_in_the_code_exists():
    """Every docs/model.md section cited in the code (the tools in selfas_graph/bench included), tests and scenes is a heading of that page."""
    headings = _model_md_headings()
    bad = []
    for path in _citing_files():
        for group in MODEL_CITE.findall(_joined(path)):
            names = [a or b for a, b in re.findall(_QUOTED, group)]
            bad += [f"{path.relative_to(ROOT)}: {name!r}" for name in names if name not in headings]
    assert not bad, f"citations of docs/model.md sections that do not exist: {sorted(set(bad))}"


#: the code cites docs/performance.md the same way, with or without a comma before the heading
PERF_CITE = re.compile(rf"docs/performance\.md,?\s+({_NAME}(?:(?:,\s*|\s+or\s+|\s+and\s+){_NAME})*)")


def test_every_docs_performance_md_section_cited_in_the_code_exists():
    """Every docs/performance.md section cited in the code, tests and scenes is a heading of that page
    (sections move to the dated log when their figures are superseded)."""
    headings = _model_md_headings("performance.md")
    cited, bad = 0, []
    for path in _citing_files():
        for group in PERF_CITE.findall(_joined(path)):
            names = [a or b for a, b in re.findall(_QUOTED, group)]
            cited += len(names)
            bad += [f"{path.relative_to(ROOT)}: {name!r}" for name in names if name not in headings]
    assert cited > 30  # not vacuous
    assert not bad, f"citations of docs/performance.md sections that do not exist: {sorted(set(bad))}"


def test_code_cites_docs_model_md_sections_by_name():
    """Section numbers move when the page grows: the code names the section instead."""
    bad = [
        str(p.relative_to(ROOT))
        for p in _citing_files()
        if re.search(r"docs/model\.md,? sections? \d", p.read_text(encoding="utf-8"))
    ]
    assert not bad, f"docs/model.md cited by section number in {bad}; cite the heading in quotes"


def test_no_citation_of_the_project_model_text():
    """Code, tools, tests and scenes cite docs/model.md, never the model text users do not have."""
    bad = [str(p.relative_to(ROOT)) for p in _citing_files() if OLD_NAME in p.read_text(encoding="utf-8")]
    assert not bad, f"{OLD_NAME} cited in {bad}; cite docs/model.md and a heading in quotes instead"
