"""Build ``../landmarks.json`` (plantreg.landmarks v1) from ``annotations.json``, and
``../landmarks_heldout.json`` from the annotations marked ``"held_out"`` (read after ``rig.json``
was fitted and kept out of its fit, to check it); each held-out point keeps its ``"held_out_kind"``
(``independent``: read without any mark of a rig's prediction, a real check; ``found_with_rig``:
located with rig.json's predictions, so it flatters that rig; README, "Session landmarks").

``annotations.json``: {"PLANT/CAMERA": [{"ir": [u, v], "other": [u, v], "note": ..., "how": ...}, ...]}
(the accepted pairs with how each was obtained). Each pair becomes one landmark point
{"depth_uv": ir, "cameras": {CAMERA: other}, "note": ...}; recording paths are relative to the
landmarks file ("recordings/01grapevine").

Session 11 (issue 23): the pairs read then (``"session"`` starting with ``s11``) go to
``../landmarks_s11.json`` (every point with ``"s11_role"``: ``fit`` or ``held_out``, and the held-out
ones' ``"held_out_kind"``), not into the two files above, as long as ``rig.json`` is not fitted to
them; ``--with-s11`` puts them into ``landmarks.json`` / ``landmarks_heldout.json`` (a rig refitted with
them shipped).

  python resources/plant3dimagereg/landmark_scripts/build_landmarks.py [--with-s11]
"""

from __future__ import annotations

import json
from pathlib import Path

HERE = Path(__file__).resolve().parent
OUT = HERE.parent / "landmarks.json"
HELD = HERE.parent / "landmarks_heldout.json"  # points kept out of rig.json's fit (annotations with "held_out")
S11 = HERE.parent / "landmarks_s11.json"  # session 11's pairs while rig.json is not fitted to them


def build(held_out: bool | None, s11: bool | None = False) -> tuple[dict, int]:
    """``held_out``: only the held-out points (True), only the others (False), all (None);
    ``s11``: only session 11's points (True), none of them (False), both (None)."""
    ann = json.loads((HERE / "annotations.json").read_text())
    recs: dict[str, dict] = {}
    for key in sorted(ann):
        plant, cam = key.split("/")
        for it in ann[key]:
            if held_out is not None and bool(it.get("held_out")) != held_out:
                continue
            is_s11 = str(it.get("session", "")).startswith("s11")
            if s11 is not None and is_s11 != s11:
                continue
            pts = recs.setdefault(f"recordings/{plant}", {"points": []})["points"]
            pts.append({"depth_uv": [round(float(x), 2) for x in it["ir"]],
                        "cameras": {cam: [round(float(x), 2) for x in it["other"]]},
                        "note": it.get("note", ""),
                        **({"held_out_kind": it["held_out_kind"]} if it.get("held_out") else {}),
                        **({"s11_role": "held_out" if it.get("held_out") else "fit"} if s11 else {})})
    return {"format": "plantreg.landmarks", "version": 1, "recordings": recs}, \
        sum(len(r["points"]) for r in recs.values())


def main(with_s11: bool = False) -> None:
    jobs = [(OUT, False, None if with_s11 else False), (HELD, True, None if with_s11 else False)]
    if not with_s11:
        jobs.append((S11, None, True))
    elif S11.exists():
        S11.unlink()
    for out, held, s11 in jobs:
        doc, n = build(held, s11)
        if held and not n:  # nothing held out: no file (a stale one would claim a check that is not there)
            out.unlink(missing_ok=True)
            print(f"{out}: no held-out points, not written")
            continue
        if s11 and not n:
            out.unlink(missing_ok=True)
            continue
        out.write_text(json.dumps(doc, indent=1) + "\n")
        print(f"{out}: {n} points in {len(doc['recordings'])} recordings")


if __name__ == "__main__":
    import sys

    main("--with-s11" in sys.argv[1:])
