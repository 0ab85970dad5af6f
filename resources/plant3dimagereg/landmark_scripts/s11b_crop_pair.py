"""Session s11b reading crops: an infrared crop and another camera's crop side by side, NO marks (no
prediction of any rig is computed here); the other camera is turned into the infrared's orientation by
annotate_view.crop_view, whose labels give the ORIGINAL coordinates. The thermal crop can be blurred
for display (sigma px) and is stretched over its in-image pixels only (a crop past the border does
not flatten the stretch). Each s11b reading used two such crops with other centres and zooms.

  python s11b_crop_pair.py PLANT U V HALF ZOOM TU TV HALFT ZOOMT OUT.png [BLUR] [CAM]
"""
import sys
sys.path.insert(0, __import__('os').path.dirname(__import__('os').path.abspath(__file__)))
import cv2, numpy as np
import annotate_view as av
plant=sys.argv[1]; u,v=float(sys.argv[2]),float(sys.argv[3]); h,z=int(sys.argv[4]),int(sys.argv[5])
tu,tv=float(sys.argv[6]),float(sys.argv[7]); ht,zt=int(sys.argv[8]),int(sys.argv[9]); out=sys.argv[10]
blur=float(sys.argv[11]) if len(sys.argv)>11 else 0.0
cam=sys.argv[12] if len(sys.argv)>12 else 'thermal'
_st=av.stretch
def st(cam,a,sh=False):
    if cam=='thermal' and a.ndim==2 and (a==0).any() and (a!=0).any():
        a=a.copy(); a[a==0]=np.median(a[a!=0])
    return _st(cam,a,sh)
av.stretch=st
a=av.crop_view(plant,'ir',u,v,h,z,[],tick=5)
if blur>0:
    orig=av.load
    av.load=lambda p,c: cv2.GaussianBlur(orig(p,c),(0,0),blur) if c=='thermal' else orig(p,c)
b=av.crop_view(plant,cam,tu,tv,ht,zt,[],tick=5,stretch_hs=True)
cv2.imwrite(out,av.hstack([a,b]))
