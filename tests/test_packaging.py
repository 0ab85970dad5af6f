"""Installing plantreg as a user: the wheel built from this checkout carries every module, the
icon and desktop entry and the version; ``plantreg-gui --install-desktop`` writes a valid entry
naming the installed program and ``--uninstall-desktop`` removes exactly that; versions and
Help ▸ About. (A full install into a fresh venv: ``packaging/check-wheel.sh``; the frozen bundle:
``packaging/smoke-bundle.sh``.)"""

from __future__ import annotations

import configparser
import os
import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

import plantreg_gui
from plantreg_gui import desktop, resources

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "plantreg_gui"


# ---------------------------------------------------------------------- the wheel
@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """The wheel built from a copy of the checkout with this environment's setuptools (offline)."""
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy2(ROOT / name, src / name)
    shutil.copytree(PKG, src / "plantreg_gui", ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index",
                        "-q", "-w", str(tmp / "dist"), str(src)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    (whl,) = (tmp / "dist").glob("plantreg-*.whl")
    return whl


def test_wheel_carries_every_module_resource_and_the_version(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    modules = {p.relative_to(ROOT).as_posix() for p in PKG.rglob("*.py") if "__pycache__" not in p.parts}
    assert len(modules) > 50
    assert modules - names == set(), "modules missing from the wheel"
    with zipfile.ZipFile(wheel) as z:
        for name in resources.FILES:
            assert z.read(f"plantreg_gui/resources/{name}") == (PKG / "resources" / name).read_bytes()
        dist = f"plantreg-{plantreg_gui.__version__}.dist-info"
        meta = z.read(f"{dist}/METADATA").decode()
        entry_points = z.read(f"{dist}/entry_points.txt").decode()
    assert wheel.name.startswith(f"plantreg-{plantreg_gui.__version__}-")
    assert re.search(rf"^Version: {re.escape(plantreg_gui.__version__)}$", meta, re.M)
    assert "plantreg = plantreg_gui.cli:entry" in entry_points
    assert "plantreg-gui = plantreg_gui.gui.app:main" in entry_points
    assert not [n for n in names if n.startswith(("tests/", "benchmarks/", "resources/"))]


def test_version_is_semantic_and_in_the_changelog():
    v = plantreg_gui.__version__
    assert re.fullmatch(r"\d+\.\d+\.\d+", v)
    log = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    assert "## [Unreleased]" in log
    released = re.findall(r"^## \[(\d+\.\d+\.\d+)\] - \d{4}-\d\d-\d\d$", log, re.M)
    assert released and released[0] == v, "the newest CHANGELOG section is not this version"


@pytest.mark.parametrize("program", ["cli", "gui"])
def test_version_options(program):
    code = ("from plantreg_gui.cli import main; main(['--version'])" if program == "cli" else
            "from plantreg_gui.gui.app import main; main(['--version'])")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                       env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert r.returncode == 0 and r.stdout == f"plantreg {plantreg_gui.__version__}\n"


# ---------------------------------------------------------------------- resources
def test_resources_are_read_from_the_package():
    icon = resources.path(resources.ICON)
    assert icon.is_file() and PKG / "resources" in icon.parents
    assert resources.read_bytes(resources.ICON).lstrip().startswith(b"<svg")
    assert b"[Desktop Entry]" in resources.read_bytes(resources.DESKTOP_ENTRY)


# ---------------------------------------------------------------------- desktop entry
def unquote_exec(value: str) -> list[str]:
    """The arguments of a desktop entry's Exec value, by the Desktop Entry Specification (key-file
    unescaping of backslashes first, then double-quoted arguments with \\" \\` \\$ \\\\ escapes)."""
    s, i, args = value.replace("\\\\", "\\").replace("%%", "%"), 0, []
    while i < len(s):
        if s[i] == " ":
            i += 1
            continue
        arg = ""
        if s[i] == '"':
            i += 1
            while s[i] != '"':
                if s[i] == "\\" and s[i + 1] in '"`$\\':
                    i += 1
                arg += s[i]
                i += 1
            i += 1
        else:
            while i < len(s) and s[i] != " ":
                arg += s[i]
                i += 1
        args.append(arg)
    return args


def read_entry(path: Path) -> dict[str, str]:
    cp = configparser.ConfigParser(interpolation=None, strict=True)
    cp.optionxform = str  # keys are case-sensitive
    cp.read_string(path.read_text(encoding="utf-8"))
    assert cp.sections() == ["Desktop Entry"]
    return dict(cp["Desktop Entry"])


def validate(path: Path) -> None:
    """desktop-file-validate (Debian's desktop-file-utils, installed by packaging/system-deps.sh)
    where installed; the structure is checked by :func:`read_entry` in any case."""
    if shutil.which("desktop-file-validate"):
        r = subprocess.run(["desktop-file-validate", str(path)], capture_output=True, text=True)
        assert r.returncode == 0 and "error" not in r.stdout, r.stdout


@pytest.mark.parametrize("exe_name", ["plantreg-gui", "plantreg gui $HOME \"q\" \\b`x` 100%"])
def test_install_and_uninstall_desktop(tmp_path, exe_name):
    home = tmp_path / "share"
    exe = tmp_path / "venv dir" / "bin" / exe_name
    exe.parent.mkdir(parents=True)
    exe.write_text("#!/bin/sh\n")
    exe.chmod(0o755)
    written = desktop.install(home, exe)
    entry = home / "applications" / "plantreg-gui.desktop"
    icon = home / "icons" / "hicolor" / "scalable" / "apps" / "plantreg.svg"
    assert sorted(written) == sorted([entry, icon])
    assert icon.read_bytes() == (PKG / "resources" / "plantreg.svg").read_bytes()
    e = read_entry(entry)
    assert e["Type"] == "Application" and e["Name"] == "plantreg" and e["Icon"] == "plantreg"
    assert e["Terminal"] == "false"
    assert unquote_exec(e["Exec"]) == [str(exe)]
    assert e["TryExec"].replace("\\\\", "\\") == str(exe)
    validate(entry)
    removed, kept = desktop.uninstall(home)
    assert sorted(removed) == sorted([entry, icon]) and kept == []
    assert [p for p in home.rglob("*") if p.is_file()] == []


def test_uninstall_leaves_what_it_did_not_install(tmp_path):
    home = tmp_path / "share"
    entry = home / "applications" / "plantreg-gui.desktop"
    icon = home / "icons" / "hicolor" / "scalable" / "apps" / "plantreg.svg"
    entry.parent.mkdir(parents=True)
    icon.parent.mkdir(parents=True)
    entry.write_text("[Desktop Entry]\nType=Application\nName=my own\nExec=true\n")
    icon.write_text("<svg>someone else's</svg>")
    removed, kept = desktop.uninstall(home)
    assert removed == [] and sorted(kept) == sorted([entry, icon])
    assert entry.is_file() and icon.is_file()


def test_data_home_follows_xdg(tmp_path):
    assert desktop.data_home({"XDG_DATA_HOME": str(tmp_path), "HOME": "/h"}) == tmp_path
    # unset, empty or relative: ignored, as the XDG base-directory specification says
    for env in ({"HOME": "/h"}, {"XDG_DATA_HOME": "", "HOME": "/h"}, {"XDG_DATA_HOME": "rel", "HOME": "/h"}):
        assert desktop.data_home(env) == Path("/h/.local/share")


def test_install_desktop_command(tmp_path):
    """``plantreg-gui --install-desktop`` names the program beside this interpreter (the venv's
    bin), writes under $XDG_DATA_HOME; ``--uninstall-desktop`` removes both files."""
    exe = Path(sys.executable).absolute().parent / "plantreg-gui"
    env = {**os.environ, "PYTHONPATH": str(ROOT), "XDG_DATA_HOME": str(tmp_path)}
    code = "import sys; from plantreg_gui.gui.app import main; sys.exit(main(sys.argv[1:]))"
    r = subprocess.run([sys.executable, "-c", code, "--install-desktop"], capture_output=True, text=True,
                       env=env, timeout=120)
    if exe.is_file():
        assert r.returncode == 0, r.stderr
        e = read_entry(tmp_path / "applications" / "plantreg-gui.desktop")
        assert unquote_exec(e["Exec"]) == [str(exe)]
        assert "PySide6" not in r.stderr
    else:  # an interpreter with no plantreg-gui beside it nor on the PATH: one line, exit 1
        assert r.returncode == 1 and r.stderr.count("\n") == 1 and "plantreg-gui" in r.stderr
        return
    r = subprocess.run([sys.executable, "-c", code, "--uninstall-desktop"], capture_output=True, text=True,
                       env=env, timeout=120)
    assert r.returncode == 0 and r.stdout.count("removed ") == 2
    assert [p for p in tmp_path.rglob("*") if p.is_file()] == []


def test_install_desktop_without_a_program(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sys, "executable", str(tmp_path / "python"))
    monkeypatch.setenv("PATH", str(tmp_path))
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "share"))
    assert desktop.main("install") == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no installed 'plantreg-gui'" in err
    assert not (tmp_path / "share").exists()


# ---------------------------------------------------------------------- Help > About
def test_about_rows_import_nothing_heavy():
    """The About dialog's versions come from metadata: opening it loads no library the window had
    not loaded (OpenCV, Open3D, SciPy would each cost the GUI thread a stall)."""
    code = ("import sys; from plantreg_gui.versions import versions; rows = dict(versions()); "
            "heavy = {'cv2', 'open3d', 'scipy', 'vtkmodules', 'numpy', 'importlib.metadata'} & set(sys.modules); "
            "print(heavy or 'none'); print(rows['OpenCV'], rows['Open3D'], rows['VTK'])")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                       env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert r.returncode == 0, r.stderr
    heavy, vers = r.stdout.splitlines()
    assert heavy == "none"
    import cv2
    import vtkmodules

    from plantreg_gui.core.geometry.o3d_core import open3d_core

    open3d_core()
    import open3d

    ocv, o3d, vtk = vers.split()
    assert ocv.startswith(cv2.__version__) and o3d == open3d.__version__ and vtk == vtkmodules.__version__


@pytest.mark.gui
def test_help_about_lists_versions_and_open_files(qapp, qtbot, no_qt_leaks, tmp_path):
    import platform

    import vtkmodules
    from PySide6.QtCore import QSettings, qVersion

    from plantreg_gui.gui.main_window import MainWindow

    for fmt in (QSettings.Format.NativeFormat, QSettings.Format.IniFormat):
        QSettings.setPath(fmt, QSettings.Scope.UserScope, str(tmp_path / "qsettings"))
    win = MainWindow()
    qtbot.addWidget(win)
    win.show()
    assert not win.windowIcon().isNull()
    try:
        rig = ROOT / "resources" / "plant3dimagereg" / "rig.json"
        win.workspace.open_rig(rig)
        assert [a.text() for a in win.help_menu.actions()] == ["About plantreg…"]
        win.about_action.trigger()
        dlg = win.about_dialog
        qtbot.waitUntil(dlg.isVisible)
        rows = dict(dlg.rows)
        assert rows["plantreg"] == plantreg_gui.__version__
        assert rows["Python"].startswith(platform.python_version())
        assert rows["Qt"] == qVersion() and rows["VTK"] == vtkmodules.__version__
        assert Path(rows["rig"]).resolve() == rig.resolve()
        assert rows["recording"] == "none open"
        assert f"plantreg: {plantreg_gui.__version__}" in dlg.plain_text()
        assert plantreg_gui.__version__ in dlg.text.text()
        dlg.grab().save(str(tmp_path / "about.png"))
        dlg.close()
    finally:
        win.close()


def test_install_desktop_refuses_a_path_with_a_line_break(tmp_path):
    from plantreg_gui.core.errors import InputError

    with pytest.raises(InputError, match="line break"):
        desktop.install(tmp_path / "share", tmp_path / "a\nb" / "plantreg-gui")
    assert not (tmp_path / "share").exists()


def test_menu_caches_refreshed_only_where_the_desktop_keeps_them(tmp_path):
    """No cache is created (uninstall could not tell it from the user's); an existing icon cache
    is rebuilt by gtk-update-icon-cache, where that tool is installed: with the new icon after
    install, without it after uninstall."""
    bare, cached = tmp_path / "bare", tmp_path / "cached"
    exe = Path(sys.executable)
    desktop.install(bare, exe)
    assert sorted(p.name for p in bare.rglob("*") if p.is_file()) == ["plantreg-gui.desktop", "plantreg.svg"]
    cache = cached / "icons" / "hicolor" / "icon-theme.cache"
    cache.parent.mkdir(parents=True)
    cache.write_bytes(b"")
    desktop.install(cached, exe)
    if shutil.which("gtk-update-icon-cache"):
        assert b"plantreg" in cache.read_bytes()
    desktop.uninstall(cached)
    # rebuilt without our icon (gtk-update-icon-cache drops a cache of a theme left with no icon)
    assert not cache.is_file() or b"plantreg" not in cache.read_bytes()
