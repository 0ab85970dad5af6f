"""A view, a modality and an output are each declared in one place; these tests fail when a
second place appears (a comparison with a view's or a modality's name elsewhere, a document that
lists views or outputs by hand and drifts, a file written by two output parts).

* views: ``plantreg_gui/gui/registration/views.py`` (``VIEWS``)
* modalities: ``plantreg_gui/core/camera/modality.py`` (``MODALITIES``)
* outputs: ``plantreg_gui/core/export/export.py`` (``OUTPUT_PARTS``)
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "plantreg_gui"


def _compared_strings(words: set[str], skip: tuple[str, ...]) -> list[str]:
    """``file:line: code`` of every comparison of a string in ``words`` in the package (``==``,
    ``!=``, ``in`` a literal tuple/list/set), outside the files under ``skip``."""
    found = []
    for f in sorted(PKG.rglob("*.py")):
        rel = f.relative_to(ROOT).as_posix()
        if rel.startswith(skip):
            continue
        for node in ast.walk(ast.parse(f.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.Compare):
                continue
            consts = []
            for c in (node.left, *node.comparators):
                elts = c.elts if isinstance(c, (ast.Tuple, ast.List, ast.Set)) else [c]
                consts += [e.value for e in elts if isinstance(e, ast.Constant) and e.value in words]
            if consts:
                found.append(f"{rel}:{node.lineno}: {ast.unparse(node)}")
    return found


# ---------------------------------------------------------------------- views
def test_views_are_named_only_in_their_registry():
    from plantreg_gui.gui.registration.views import VIEWS

    words = {v.key for v in VIEWS} - {"raw"}  # "raw" is also the word for raw images everywhere
    # the registry, and each view's own module (a view may name its own modes)
    own = ("plantreg_gui/gui/registration/views.py", "plantreg_gui/gui/registration/cloud_view.py",
           "plantreg_gui/gui/registration/mosaic_view.py", "plantreg_gui/gui/registration/masks_view.py",
           "plantreg_gui/gui/registration/image_views.py")
    assert not _compared_strings(words, own)


def test_view_lists_come_from_the_registry():
    from plantreg_gui.gui.app import build_parser
    from plantreg_gui.gui.registration.views import view_keys

    keys = view_keys()
    view = next(a for a in build_parser()._actions if "--view" in a.option_strings)
    assert view.help.endswith(": " + ", ".join(keys))
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    m = re.search(r"`--view\s+([\w|-]+)", readme)
    assert m and m.group(1).split("|") == keys, "README's --view list differs from views.VIEWS"
    doc = (ROOT / "docs" / "workspace.md").read_text(encoding="utf-8")
    m = re.search(r"`--view` is one of ((?:`[\w-]+`(?:, )?)+)", doc)
    assert m and re.findall(r"`([\w-]+)`", m.group(1)) == keys, "docs/workspace.md's --view list differs"


# ---------------------------------------------------------------------- modalities
#: Where comparing modality names is the point: the synthetic sensors simulate each modality's
#: physics (any other modality is rendered as a grey reflectance image, so a new modality needs
#: nothing there); core/calibration/synthetic.py's board renderer likewise (kept as it is while
#: the calibration work of issue 19 changes that package).
MODALITY_SKIP = ("plantreg_gui/core/camera/modality.py", "plantreg_gui/core/synthetic/",
                 "plantreg_gui/core/calibration/synthetic.py")


def test_modalities_are_named_only_in_their_registry():
    from plantreg_gui.core.camera.modality import MODALITIES

    words = {n for m in MODALITIES for n in (m.name, *m.aliases)}
    # "depth" is also the recording's role of the depth map (manifest key, the depth camera): a
    # comparison with it is a modality test only when it reads a modality
    found = [f for f in _compared_strings(words - {"depth"}, MODALITY_SKIP)]
    found += [f for f in _compared_strings({"depth"}, MODALITY_SKIP) if "modality" in f or "mod." in f]
    assert not found


def test_a_new_modality_is_one_entry(monkeypatch):
    """A modality added to the registry is canonicalised, coloured, given its unit and cube rule."""
    from plantreg_gui.core.camera import modality

    new = modality.Modality("fluorescence", ("chlorophyll-fluorescence", "cf"), "magma", "a.u.", False, 1,
                            "fluorescence")
    monkeypatch.setattr(modality, "MODALITIES", (*modality.MODALITIES, new))
    monkeypatch.setattr(modality, "_BY_NAME", {**modality._BY_NAME, "fluorescence": new, "cf": new,
                                               "chlorophyll-fluorescence": new})
    assert modality.canonical("CF") == "fluorescence" and modality.default_cmap("cf") == "magma"
    assert modality.unit("fluorescence") == "a.u." and not modality.is_colour("cf")
    assert not modality.is_cube_image("cf", 1) and modality.is_cube_image("cf", 12)


# ---------------------------------------------------------------------- outputs
def test_each_file_belongs_to_one_output_part(tmp_path):
    """Writing each part alone gives disjoint sets of files whose union is the full output."""
    from test_export import _result

    from plantreg_gui.core.export import export

    rig, res = _result()
    res.flying = res.area == 6  # a flying-pixel mask, so that every part has something to write
    res.mixed = {c: v == 1 for c, v in res.cases.items()}

    def files(folder: Path) -> set[str]:
        return {p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()} - {"summary.json"}

    full = files(export.write_outputs(res, rig, None, tmp_path / "all"))
    seen: dict[str, str] = {}
    for part in export.OUTPUTS:
        if part == "summary":
            continue
        for f in files(export.write_outputs(res, rig, None, tmp_path / part, what=(part,))):
            assert f not in seen, f"{f} is written by both '{seen[f]}' and '{part}'"
            seen[f] = part
    assert set(seen) == full


@pytest.mark.parametrize("doc", ["README.md", "docs/outputs.md"])
def test_output_lists_come_from_the_registry(doc):
    from plantreg_gui.core.export.export import output_choices

    text = (ROOT / doc).read_text(encoding="utf-8")
    lists = re.findall(r"`(?:--outputs\s+(?:PARTS` \(comma-separated: `)?)([a-z,]+)`", text.replace("\n", " "))
    # the document lists every part once, and its examples use only parts that exist
    assert output_choices() in lists, (lists, output_choices())
    assert all(set(x.split(",")) <= set(output_choices().split(",")) for x in lists), lists
