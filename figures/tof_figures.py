"""The issue-9 figures per seed and source on the realistic ToF scene (docs/registration.md section 9 tables).

    PYTHONPATH=. .venv/bin/python figures/tof_figures.py 0,1,2,3,4,5,6,7

Per seed and source, one markdown row: median / 90th percentile mapping error, P1 coverage, P1 truly
visible, occluded -> P2/P3.2 with the clean-up, the same without hole filling, without any clean-up
(median / occluded), and with exact depth (P1 coverage / occluded); the observability bound (share of truly
matchable pixels whose view of the source lies in space the depth camera observes:
``synthetic.render.observable_views``) and P1 coverage of those pixels; then the mean leaf temperature
errors (all P1, unflagged P1, share flagged, error of the flagged). Ground truth from the synthetic
generator; the scene is ``tests/test_tof.py``'s ``_realistic(seed)``. Not part of the test run.
"""
import sys, numpy as np
sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1] / "tests"))
import test_tof as T
from test_register import figures
from plantreg_gui.core.data.recording import Recording
from plantreg_gui.core.registration.register import register, RegistrationParams
from plantreg_gui.core.registration.cases import Case
from plantreg_gui.core.synthetic import MAT_LEAF0, render_depth
from plantreg_gui.core.synthetic.render import observable_views
from plantreg_gui.core.synthetic.textures import Appearance
from test_register import in_roi
for seed in [int(s) for s in sys.argv[1].split(",")]:
    rig, scene, rec, gt = T._realistic(seed)
    res = register(rig, rec, "ir")
    off = register(rig, rec, "ir", RegistrationParams(flying_filter=False, denoise=False, fill_holes=False))
    nofill = register(rig, rec, "ir", RegistrationParams(fill_holes=False))
    ideal = register(rig, Recording(None, render_depth(rig, scene), {}), "ir")
    obs = observable_views(rig, scene, gt)
    for src in res.cases:
        f, o, n, i = (figures(rig, r, gt, src) for r in (res, off, nofill, ideal))
        match = gt.matchable[src] & in_roi(rig, gt)
        ob = obs[src] & match
        bound = ob.sum() / match.sum()
        cov_ob = ((res.cases[src] == Case.P1) & ob).sum() / ob.sum()
        print(f"| {seed} | {src} | {f['median']:.3f} | {f['p90']:.3f} | {100*f['p1_coverage']:.1f} % | {100*f['p1_visible']:.2f} % | {100*f['occluded_p2_p32']:.1f} % | {100*n['occluded_p2_p32']:.1f} % | {o['median']:.3f} / {100*o['occluded_p2_p32']:.1f} % | {100*i['p1_coverage']:.1f} % / {100*i['occluded_p2_p32']:.1f} % | {100*bound:.1f} % | {100*cov_ob:.2f} % |", flush=True)
    cam = rig.camera("ir"); o_, d_ = cam.rays_rig(); _t, prim, bary = scene.cast(o_, d_); hit = prim >= 0
    s = scene.surface(prim[hit], bary[hit]); Tt = np.full(len(d_), np.nan)
    Tt[hit] = Appearance(scene).temperature(s["points"], s["material"], s["uv"]); Tt = Tt.reshape(cam.shape)
    leaf = gt.material >= MAT_LEAF0
    reg = res.registered["thermal"]; p1 = (res.cases["thermal"] == Case.P1) & leaf; mx = res.mixed["thermal"]
    sel = p1 & ~mx
    print(f"TEMP | {seed} | {np.mean(reg[p1]) - np.mean(Tt[p1]):+.3f} °C | {np.mean(reg[sel]) - np.mean(Tt[sel]):+.3f} °C | {100*(p1&mx).sum()/p1.sum():.1f} % | {np.mean(reg[p1&mx]) - np.mean(Tt[p1&mx]):+.2f} °C |", flush=True)
