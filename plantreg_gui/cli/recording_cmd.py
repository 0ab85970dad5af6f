"""``plantreg recording create``: a recording.json for files that live anywhere.

    plantreg recording create DIR --depth FILE [--depth-scale S] --image NAME=FILE [--image ...] [--overwrite]

Writes ``DIR/recording.json`` with paths relative to DIR (the files are not copied; labs keep
their own names and folders), after checking that every file is a readable image and the depth
map is single-channel. ``--depth-scale`` (metres per depth unit) overrides the rig's for this
recording.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from ..core.errors import InputError


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    from . import nonempty_path

    p = sub.add_parser("recording", help="make recording folders (recording.json) for existing files",
                       description="Recording folders: a recording.json naming a depth map and one image per camera.")
    rs = p.add_subparsers(dest="recording_command", metavar="ACTION", required=True)
    c = rs.add_parser("create", help="write DIR/recording.json pointing at existing files",
                      description="Write DIR/recording.json pointing at existing files (paths stored relative to "
                      "DIR; nothing is copied). Every file must be a readable image.")
    c.add_argument("dir", type=nonempty_path, metavar="DIR", help="recording folder (made if missing)")
    c.add_argument("--depth", type=nonempty_path, metavar="FILE", help="depth map of the rig's depth camera")
    c.add_argument("--depth-scale", type=float, metavar="S",
                   help="metres per depth unit of this recording (default: the rig's depth.scale)")
    c.add_argument("--image", action="append", default=[], metavar="NAME=FILE",
                   help="image of camera NAME (repeatable)")
    c.add_argument("--overwrite", action="store_true", help="replace an existing DIR/recording.json")
    c.set_defaults(run=run_create)
    return p


def run_create(args: argparse.Namespace) -> int:
    from ..core.io.imageio import atomic_write_text, read_image
    from ..core.io.lock import claim_output
    from ..core.data.recording import MANIFEST, manifest_entries

    folder: Path = args.dir
    manifest = folder / MANIFEST
    if args.depth is None and not args.image:
        raise InputError("give --depth FILE and/or --image NAME=FILE")
    if args.depth_scale is not None:
        from ..core.validate import depth_scale

        try:
            depth_scale(args.depth_scale, "--depth-scale")
        except ValueError as e:
            raise InputError(str(e)) from None
    images: dict[str, Path] = {}
    for item in args.image:
        name, sep, f = item.partition("=")
        if not sep or not name or not f:
            raise InputError(f"--image takes NAME=FILE, got '{item}'")
        if name == "depth":
            raise InputError("'depth' is not a camera name: give the depth map with --depth")
        if name in images:
            raise InputError(f"camera '{name}' is given twice with --image")
        images[name] = Path(f)
    m: dict[str, object] = {}
    if args.depth is not None:
        m["depth"] = _rel(args.depth, folder)
        if args.depth_scale is not None:
            m["depth_scale"] = args.depth_scale
    m["images"] = {name: _rel(f, folder) for name, f in images.items()}
    # the manifest as register will read it: its camera names under the one rule (core/validate.py)
    manifest_entries(m, manifest)
    if os.path.lexists(folder) and not folder.is_dir():
        raise InputError("recording folder is a file, not a folder", folder)
    inputs = [*images.values(), *([args.depth] if args.depth is not None else [])]
    with claim_output(manifest, MANIFEST, overwrite=args.overwrite, inputs=inputs):
        # read every file now: a recording that cannot be read later is no use
        for name, f in images.items():
            read_image(f)
        if args.depth is not None:
            d = read_image(args.depth)
            if d.ndim != 2:
                raise InputError(f"depth map must be single-channel, got shape {d.shape}", args.depth)
            if d.dtype.kind not in "uif":
                raise InputError(f"depth map must hold numbers, got dtype {d.dtype}", args.depth)
        folder.mkdir(parents=True, exist_ok=True)
        atomic_write_text(manifest, json.dumps(m, indent=2) + "\n")
    print(f"wrote {manifest}: " + ", ".join((["depth"] if "depth" in m else []) + list(images)))
    return 0


def _rel(path: Path, folder: Path) -> str:
    """``path`` relative to ``folder`` (forward slashes), or absolute where no relative path exists."""
    a, b = Path(path).absolute(), Path(folder).absolute()
    try:
        return Path(os.path.relpath(a, b)).as_posix()
    except ValueError:  # another drive (Windows)
        return a.as_posix()
