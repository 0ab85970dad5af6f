"""``plantreg-gui --install-desktop`` / ``--uninstall-desktop``: the applications-menu entry and
icon of the installed program, for the current user (freedesktop.org XDG layout). Qt-free.

Installs two files and nothing else:

- ``$XDG_DATA_HOME/applications/plantreg-gui.desktop`` (``~/.local/share`` when
  ``XDG_DATA_HOME`` is unset, empty or relative, as the XDG base-directory spec says), whose
  ``Exec`` and ``TryExec`` name the installed ``plantreg-gui`` by its absolute path (a pipx or
  venv install is usually not on the PATH the desktop session starts programs with);
- ``$XDG_DATA_HOME/icons/hicolor/scalable/apps/plantreg.svg``.

The entry carries :data:`MARKER`, so that uninstalling removes exactly these files (a launcher of
the same name written by someone else is left alone). Menu caches are refreshed only where the
desktop already keeps one (``mimeinfo.cache``, ``icon-theme.cache``) and its tool is installed:
without a cache the directories are read directly, and creating one would leave a file behind
that uninstalling could not tell from the user's.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

from . import resources

ENTRY_NAME = resources.DESKTOP_ENTRY
ICON_NAME = resources.ICON  # found by its theme name "plantreg" (the entry's Icon=)
MARKER = "X-plantreg-Installed-By"
PROGRAM = "plantreg-gui"


def data_home(env: dict[str, str] | None = None) -> Path:
    """``$XDG_DATA_HOME`` if set to an absolute path, else ``~/.local/share``."""
    env = os.environ if env is None else env
    d = env.get("XDG_DATA_HOME", "")
    if d and os.path.isabs(d):
        return Path(d)
    return Path(env.get("HOME") or Path.home()) / ".local" / "share"


def entry_path(home: Path) -> Path:
    return home / "applications" / ENTRY_NAME


def icon_path(home: Path) -> Path:
    return home / "icons" / "hicolor" / "scalable" / "apps" / ICON_NAME


def installed_executable() -> Path:
    """The ``plantreg-gui`` program this process belongs to, as an absolute path: the frozen
    bundle's executable, else the script beside this interpreter (a venv's or pipx's ``bin``;
    the interpreter's symlink is not resolved, which would leave the venv), else the one on the
    PATH. Raises :class:`~plantreg_gui.core.errors.InputError` when there is none."""
    if getattr(sys, "frozen", False):
        return Path(sys.executable).absolute()
    exe_dir = Path(sys.executable).absolute().parent
    for cand in (exe_dir / PROGRAM, exe_dir / f"{PROGRAM}.exe"):
        if cand.is_file() and os.access(cand, os.X_OK):
            return cand
    found = shutil.which(PROGRAM)
    if found:
        return Path(found).absolute()
    from .core.errors import InputError

    raise InputError(f"no installed '{PROGRAM}' program found beside {sys.executable} or on the PATH "
                     "(install plantreg with pip or pipx first)")


def exec_arg(path: Path) -> str:
    """``path`` as one argument of a desktop entry's ``Exec`` key: quoted when it has a reserved
    character, with the quoting rules' escapes, ``%`` doubled, then the key-file escape of
    backslashes (Desktop Entry Specification, "The Exec key")."""
    s = str(path)
    reserved = set(" \t\n\"'\\><~|&;$*?#()`")
    if any(c in reserved for c in s):
        s = '"' + "".join("\\" + c if c in '"`$\\' else c for c in s) + '"'
    return s.replace("%", "%%").replace("\\", "\\\\")  # a literal % is %% (field codes)


def desktop_entry(exe: Path) -> str:
    """The packaged launcher with ``Exec``/``TryExec`` naming ``exe`` and the :data:`MARKER`."""
    out = []
    for line in resources.read_bytes(ENTRY_NAME).decode("utf-8").splitlines():
        key = line.split("=", 1)[0].strip()
        if key == "Exec":
            line = f"Exec={exec_arg(exe)}"
            out.append(f"TryExec={str(exe).replace(chr(92), chr(92) * 2)}")
        elif key in ("TryExec", MARKER):
            continue
        out.append(line)
    out.append(f"{MARKER}={PROGRAM} --install-desktop")
    return "\n".join(out) + "\n"


def _is_ours(entry: Path) -> bool:
    try:
        text = entry.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return False
    return any(line.startswith(MARKER + "=") for line in text.splitlines())


def _write(path: Path, data: bytes) -> None:
    from .core.io.imageio import atomic_path

    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    os.chmod(path, 0o644)


def _refresh_caches(home: Path) -> list[str]:
    """Refresh the menu and icon caches the desktop already keeps there; returns the commands run."""
    ran = []
    apps, hicolor = home / "applications", home / "icons" / "hicolor"
    for cache, cmd in ((apps / "mimeinfo.cache", ["update-desktop-database", "-q", str(apps)]),
                       (hicolor / "icon-theme.cache", ["gtk-update-icon-cache", "-q", "-t", "-f", str(hicolor)])):
        if cache.is_file() and shutil.which(cmd[0]):
            subprocess.run(cmd, check=False, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=60)
            ran.append(cmd[0])
    return ran


def install(home: Path | None = None, exe: Path | None = None) -> list[Path]:
    """Write the desktop entry and the icon under ``home`` (default :func:`data_home`); returns
    the two paths written."""
    home = data_home() if home is None else Path(home)
    exe = installed_executable() if exe is None else Path(exe)
    if any(c in str(exe) for c in "\n\r"):
        from .core.errors import InputError

        raise InputError(f"a desktop entry cannot name a program whose path has a line break: {exe!r}")
    icon, entry = icon_path(home), entry_path(home)
    had_icon = icon.exists()
    _write(icon, resources.read_bytes(ICON_NAME))
    try:
        _write(entry, desktop_entry(exe).encode("utf-8"))
    except BaseException:
        if not had_icon:  # no icon left behind without its entry
            icon.unlink(missing_ok=True)
        raise
    _refresh_caches(home)
    return [entry, icon]


def uninstall(home: Path | None = None) -> tuple[list[Path], list[Path]]:
    """Remove what :func:`install` wrote under ``home``; returns (removed, left alone). A
    launcher without the marker is left alone, and so is an icon of that name that is not one of
    ours (neither the entry was ours nor the bytes are the packaged icon)."""
    home = data_home() if home is None else Path(home)
    icon, entry = icon_path(home), entry_path(home)
    removed, kept = [], []
    ours = _is_ours(entry)
    if entry.exists():
        (removed if ours else kept).append(entry)
    if icon.exists():
        try:
            same = icon.read_bytes() == resources.read_bytes(ICON_NAME)
        except OSError:
            same = False
        (removed if ours or same else kept).append(icon)
    for p in removed:
        p.unlink()
    if removed:
        _refresh_caches(home)
    return removed, kept


def main(action: str) -> int:
    """The command-line face: ``action`` is "install" or "uninstall"; one line per file."""
    from .core.errors import PlantregError

    try:
        if action == "install":
            for p in install():
                print(f"installed {p}")
            print(f"plantreg is in the applications menu (it runs {installed_executable()})")
            return 0
        removed, kept = uninstall()
        for p in removed:
            print(f"removed {p}")
        for p in kept:
            print(f"left {p}: not installed by {PROGRAM} --install-desktop")
        if not removed and not kept:
            print(f"nothing to remove: no desktop entry or icon under {data_home()}")
        return 0
    except PlantregError as e:
        print(f"{PROGRAM}: error: {e}", file=sys.stderr)
        return 1
    except OSError as e:
        where = f"{e.filename}: " if e.filename else ""
        print(f"{PROGRAM}: error: {where}{e.strerror or e}", file=sys.stderr)
        return 1
