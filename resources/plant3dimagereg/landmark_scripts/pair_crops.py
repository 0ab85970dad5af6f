"""Pair crops for reading a landmark by eye: infrared crop | other camera crop (turned to the
infrared's orientation), several pairs per PNG. The other crop is centred on a given pixel or, if
none is given, on the infrared pixel's *predicted* position (depth + a rough pose from
``/tmp/ann/pose_<cam>.json`` or, with FITTED=1, the fitted rig's infrared) — a navigation aid
only: the landmark is read from the grid, never taken from the prediction. NOMARK=1 hides the
crosses (for the independent second reading). Crop size/zoom: env HI ZI HO ZO, columns NCOL.

  NOMARK=1 HI=12 ZI=9 HO=24 ZO=5 python pair_crops.py PLANT CAM OUT.png U,V[:UO,VO] ...
"""
import sys, os, json
from pathlib import Path

import numpy as np, cv2

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[2]))  # the project root (plantreg_gui)
from plantreg_gui.core.camera.camera import Camera
from annotate_view import load, crop_view, hstack
plant,cam,out=sys.argv[1:4]
hi,zi,ho,zo=[int(os.environ.get(k,v)) for k,v in (('HI',20),('ZI',5),('HO',36),('ZO',3))]
rig=json.load(open(HERE.parent / 'rig_nominal.json'))
cams={c['name']:c for c in rig['cameras']}
ir=Camera.from_dict(cams['ir']); C=Camera.from_dict(cams[cam])
if os.environ.get('FITTED'):
    fr={c['name']:c for c in json.load(open(HERE.parent / 'rig.json'))['cameras']}; ir=Camera.from_dict(fr['ir'])
try:
    pose=json.load(open(f'/tmp/ann/pose_{cam}.json')); C.R_cam_rig=np.array(pose['R']); C.t_cam_rig=np.array(pose['t'])
    if 'K' in pose: C.K=np.array(pose['K'])
except FileNotFoundError: pass
d=load(plant,'depth').astype(float)
def predict(uv):
    u,v=uv; iu,iv=int(round(u)),int(round(v)); blk=d[iv-3:iv+4,iu-3:iu+4]; blk=blk[blk>0]
    z=np.median(blk) if blk.size else 1000.
    X=ir.rays_cam(np.array([[u,v]]))[0]*z/1000
    return C.project(X[None])[0][0]
rows=[]
for k,spec in enumerate(sys.argv[4:]):
    if ':' in spec: a,b=spec.split(':'); p=tuple(map(float,a.split(','))); q=tuple(map(float,b.split(',')))
    else: p=tuple(map(float,spec.split(','))); q=tuple(predict(p))
    ti=5 if zi>=5 else 10; to=5 if zo>=5 else 10
    nm=os.environ.get('NOMARK')
    v1=crop_view(plant,'ir',p[0],p[1],hi,zi,[] if nm else [p],tick=ti,title=f'#{k}')
    v2=crop_view(plant,cam,q[0],q[1],ho,zo,[] if nm else [q],tick=to,title=f'#{k}',stretch_hs=True)
    rows.append(hstack([v1,v2]))
w=max(r.shape[1] for r in rows)
rows=[np.pad(r,((0,4),(0,w-r.shape[1]+10),(0,0)),constant_values=255) for r in rows]
ncol=int(os.environ.get('NCOL',2))
while len(rows)%ncol: rows.append(np.full_like(rows[0],255))
cv2.imwrite(out,np.concatenate([np.concatenate(rows[j:j+ncol],1) for j in range(0,len(rows),ncol)],0))
