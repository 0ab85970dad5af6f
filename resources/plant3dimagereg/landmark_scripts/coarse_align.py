"""Coarse silhouette alignment (navigation aid only; never a landmark): for each plant and camera, the
similarity transform (rotation near the nominal +-90 deg, scale near 1.8 / 2.2, shift) that best overlaps
the blurred infrared plant mask (depth nearer than the tray) with the other camera's plant mask, by
brute force. Used (a) to centre annotation crops and (b) for the rough translations of the nominal
rig (grapevine). Writes /tmp/ann/coarse.json. Slow (minutes); run with nice.
"""
import numpy as np, cv2, json, sys
sys.path.insert(0, __import__('os').path.dirname(__file__))
from annotate_view import load
P=['01grapevine','02leopard_lily','03areca_palm','04philodendron','05boston_fern','06weeping_fig']
def irmask(p):
    d=load(p,'depth')
    m=((d>0)&(d<1130)).astype(np.uint8)
    m=cv2.morphologyEx(m,cv2.MORPH_OPEN,np.ones((3,3),np.uint8))
    n,lab,st,cen=cv2.connectedComponentsWithStats(m)
    # component(s) overlapping the central region
    best=[i for i in range(1,n) if st[i,4]>300 and np.any(lab[200:380,220:420]==i)]
    return np.isin(lab,best).astype(np.float32)
def hsmask(p):
    hs=load(p,'hyperspectral').astype(np.float32); b,g,r=hs[...,0],hs[...,1],hs[...,2]
    return ((g>b*1.15)&(g>40)).astype(np.float32)
def thmask(p):
    th=load(p,'thermal'); tb=cv2.GaussianBlur(th,(0,0),2); bg=np.median(tb)
    return (np.abs(tb-bg)>0.35).astype(np.float32)
res={}
for p in P:
    mi=irmask(p)
    cv2.imwrite(f'/tmp/ann/mask_{p}_ir.png',(mi*255).astype(np.uint8))
    for cam,mf,rot0,s0 in [('hyperspectral',hsmask,+90,1.8),('thermal',thmask,-90,2.2)]:
        mo=mf(p); cv2.imwrite(f'/tmp/ann/mask_{p}_{cam}.png',(mo*255).astype(np.uint8))
        H,W=mo.shape
        a=cv2.GaussianBlur(mi,(0,0),3); b=cv2.GaussianBlur(mo,(0,0),5)
        ci=np.array(np.nonzero(mi)[::-1]).mean(1); co=np.array(np.nonzero(mo)[::-1]).mean(1)
        best=(-1,None)
        for rot in np.arange(rot0-15,rot0+16,3):
            for s in s0*np.array([0.7,0.8,0.9,1.0,1.1,1.2,1.35]):
                M=cv2.getRotationMatrix2D((float(ci[0]),float(ci[1])),float(rot),float(s))
                M[:,2]+=co-ci
                for dx in range(-60,61,10):
                    for dy in range(-60,61,10):
                        M2=M.copy(); M2[:,2]+=(dx,dy)
                        w=cv2.warpAffine(a,M2,(W,H))
                        sc=(w*b).sum()/np.sqrt((w*w).sum()*(b*b).sum()+1e-9)
                        if sc>best[0]: best=(sc,M2,rot,s)
        sc,M,rot,s=best
        # polish with ECC affine
        try:
            M32=M.astype(np.float32)
            _,M32=cv2.findTransformECC(cv2.warpAffine(a,np.eye(2,3,dtype=np.float32),(W,H))*0+b, cv2.warpAffine(a,np.eye(2,3,dtype=np.float32),(a.shape[1],a.shape[0])),M32,cv2.MOTION_AFFINE,(cv2.TERM_CRITERIA_EPS|cv2.TERM_CRITERIA_COUNT,100,1e-5),None,5)
        except Exception as e: print('ecc fail',e)
        res[f'{p}/{cam}']={'M':M.tolist(),'score':float(sc),'rot':float(rot),'s':float(s)}
        w=cv2.warpAffine(mi,M,(W,H))
        vis=np.stack([mo*255,w*255,np.zeros_like(mo)],-1).astype(np.uint8)
        cv2.imwrite(f'/tmp/ann/align_{p}_{cam}.png',vis)
        print(p,cam,round(sc,3),rot,round(s,2))
json.dump(res,open('/tmp/ann/coarse.json','w'))
