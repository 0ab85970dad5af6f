"""Export parts are one registry (core.export.OUTPUT_PARTS): the command line's --outputs, the
GUI's export dialog and the progress weights all read it; an output added there is written,
selectable, listed in summary.json and reported in the progress."""

import json

import pytest

from plantreg_gui.core.export import export
from plantreg_gui.core.errors import InputError
from plantreg_gui.core.progress import Reporter

from test_export import _result  # a hand-made result with known content


def _extra_part():
    def write(ctx, kind, cam, rep):
        (ctx.folder / "extra.txt").write_text(f"{ctx.result.target} {len(ctx.cams)}\n")
        return "extra.txt"

    return export.OutputPart("extra", "An extra part (text)", lambda r, cams: [("extra", 5.0)], write, cli="xtra")


def test_default_parts_and_cli_names():
    assert export.OUTPUTS == tuple(p.key for p in export.OUTPUT_PARTS)
    assert export.OUTPUT_PARTS[-1].key == "summary"  # lists the files written before it
    assert export.parse_outputs("ply,cases") == ("cases", "pointcloud")
    assert export.parse_outputs(None) == export.OUTPUTS
    with pytest.raises(InputError, match="choose from registered,previews,cases,edges,flying,areas,ply,mosaic,summary"):
        export.parse_outputs("nope")


def test_a_part_added_to_the_registry_is_selectable_written_and_reported(tmp_path, monkeypatch):
    monkeypatch.setattr(export, "OUTPUT_PARTS", (*export.OUTPUT_PARTS[:-1], _extra_part(), export.OUTPUT_PARTS[-1]))
    assert export.parse_outputs("xtra,summary") == ("extra", "summary")
    rig, res = _result()
    seen = []
    rep = Reporter(callback=lambda f, m: seen.append((f, m)))
    out = export.write_outputs(res, rig, None, tmp_path / "out", what=export.parse_outputs("cases,xtra,summary"),
                               progress=rep)
    assert (out / "extra.txt").read_text() == "ir 4\n"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["files"] == ["cases/rgb.png", "cases/thermal.png", "cases/hs.png", "extra.txt", "summary.json"]
    assert "extra" in summary["export_timings"]
    # weight 5 of 5 + 3 x 0.3: the extra step starts at 0.9 / 5.9 of the bar
    start = next(f for f, m in seen if m == "writing extra")
    assert start == pytest.approx(0.9 / 5.9)
    assert not (out / "areas.png").exists()
