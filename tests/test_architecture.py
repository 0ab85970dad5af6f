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
