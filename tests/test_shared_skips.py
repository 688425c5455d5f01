"""A clone with nothing beside it passes `make test`: every test that reads ../shared says so.

CI always has ../shared beside the clone, so a test that reads it without a skip passes there and
fails only on a user's machine. This check runs everywhere: it reads the test sources and names each
test function that uses a ../shared path (SHARED, CORPUS, DWH from helpers, or a module constant or
helper function made from them) without `requires_shared` (on the test or as the module's `pytestmark`) or the helm tests'
`corpus` fixture, which skips the same way.
"""
from __future__ import annotations

import ast
from pathlib import Path

TESTS = Path(__file__).resolve().parent
SHARED_NAMES = {"SHARED", "CORPUS", "DWH"}


def _names(node: ast.AST) -> set[str]:
    return {n.id for n in ast.walk(node) if isinstance(n, ast.Name)}


def _marks_shared(decorators: list[ast.expr]) -> bool:
    return any("requires_shared" in _names(d) for d in decorators)


def unmarked_readers(path: Path, root: Path = TESTS) -> list[str]:
    """`file:line test_name` of each test in `path` that reads ../shared without skipping without it."""
    tree = ast.parse(path.read_text(), str(path))
    tainted = set(SHARED_NAMES)
    module_marked = False
    for _ in range(2):      # module constants and helper functions made from a shared path read it too
        for stmt in tree.body:
            if isinstance(stmt, ast.Assign):
                targets = {t.id for t in stmt.targets if isinstance(t, ast.Name)}
                if "pytestmark" in targets and "requires_shared" in _names(stmt.value):
                    module_marked = True
                elif _names(stmt.value) & tainted:
                    tainted |= targets
            elif isinstance(stmt, ast.FunctionDef) and not stmt.name.startswith("test") and _names(stmt) & tainted:
                tainted.add(stmt.name)
    if module_marked:
        return []
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef) and node.name.startswith("test"):
            reads = _names(node) & tainted or any(_names(d) & tainted for d in node.decorator_list)
            skips = _marks_shared(node.decorator_list) or "corpus" in {a.arg for a in node.args.args}
            if reads and not skips:
                found.append(f"{path.relative_to(root)}:{node.lineno} {node.name}")
    return found


def test_every_test_reading_shared_skips_without_it():
    sources = [p for p in sorted(TESTS.rglob("*.py")) if p.name != "helpers.py" and "data" not in p.parts]
    assert len(sources) > 50
    offenders = [line for p in sources for line in unmarked_readers(p)]
    assert offenders == [], "mark these @requires_shared(...) (tests/helpers.py): a bare clone fails them"


def test_the_check_finds_an_unmarked_reader(tmp_path):
    """The check itself: unmarked tests reading a derived constant or a helper are found, marked ones not."""
    source = tmp_path / "test_x.py"
    source.write_text("from helpers import CORPUS, requires_shared\nFOLDER = CORPUS / 'ufld_alpha'\n\n"
                      "def test_reads():\n    assert FOLDER.exists()\n\n"
                      "def read(name):\n    return (FOLDER / name).read_text()\n\n"
                      "def test_reads_through_a_helper():\n    assert read('a.moos')\n\n"
                      "@requires_shared('missions-corpus')\ndef test_marked():\n    assert FOLDER.exists()\n\n"
                      "def test_fixture(corpus):\n    assert corpus.exists()\n\n"
                      "def test_unrelated():\n    assert True\n")
    assert unmarked_readers(source, tmp_path) == ["test_x.py:4 test_reads", "test_x.py:10 test_reads_through_a_helper"]
