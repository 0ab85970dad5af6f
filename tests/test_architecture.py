"""The core is pure computation: importing it must not pull in Qt or any GUI code."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

BLOCKER = r"""
import sys, importlib, pkgutil
class Block:
    BANNED = ("PySide6", "PyQt5", "PyQt6", "shiboken6", "pyvistaqt", "plantreg_gui.gui")
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in self.BANNED or name.startswith("plantreg_gui.gui"):
            raise ImportError(f"core imported GUI module {name}")
        return None
sys.meta_path.insert(0, Block())
import plantreg_gui.core as core
names = [m.name for m in pkgutil.walk_packages(core.__path__, "plantreg_gui.core.")]
for n in names:
    importlib.import_module(n)
print(len(names))
"""


def test_core_imports_without_qt():
    out = subprocess.run([sys.executable, "-c", BLOCKER], cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert int(out.stdout.strip()) >= 5  # the walk really imported the core modules


def test_import_linter_contract():
    from importlinter.cli import lint_imports

    assert lint_imports(config_filename=str(ROOT / "pyproject.toml")) == 0


def test_no_import_cycle():
    """No module of the package imports (directly or through others) a module that imports it,
    function-level imports included: a circle hidden inside a function is still a circle."""
    import grimp

    g = grimp.build_graph("plantreg_gui")
    cycles = sorted({tuple(sorted((m, n))) for m in g.modules if m.startswith("plantreg_gui")
                     for n in g.find_modules_directly_imported_by(m)
                     if n.startswith("plantreg_gui") and g.chain_exists(importer=n, imported=m)})
    assert not cycles, cycles


#: A module longer than this says why in its docstring, in a paragraph starting "Length:".
MAX_LINES = 500


def test_long_modules_say_why():
    import ast

    long_ones = []
    for f in sorted((ROOT / "plantreg_gui").rglob("*.py")):
        text = f.read_text(encoding="utf-8")
        if text.count("\n") <= MAX_LINES:
            continue
        doc = ast.get_docstring(ast.parse(text)) or ""
        if "Length:" not in doc:
            long_ones.append(f"{f.relative_to(ROOT)} ({text.count(chr(10))} lines)")
    assert not long_ones, "modules over 500 lines without a 'Length:' reason in their docstring: " + ", ".join(long_ones)


def test_core_parts_have_docstrings():
    """Every part (sub-package) of the core says what it is for."""
    import ast

    missing = [str(p.relative_to(ROOT)) for p in sorted((ROOT / "plantreg_gui" / "core").rglob("__init__.py"))
               if not ast.get_docstring(ast.parse(p.read_text(encoding="utf-8")))]
    assert not missing, missing
