"""Session s11b navigation view: a region [U0, U1) x [V0, V1) of one camera's image (ir, irhp, depth,
thermal, hyperspectral) turned into the infrared's orientation, with a grid every STEP pixels labelled
in the ORIGINAL coordinates; the stretch is computed over the region only (whole-image thermal views
without the zero padding of a square crop). Used to find the same structure in both images by eye.

  python s11b_turned_region.py PLANT CAM U0 V0 U1 V1 ZOOM STEP OUT.png [BLUR]
"""
import sys
sys.path.insert(0, __import__('os').path.dirname(__import__('os').path.abspath(__file__)))
import cv2, numpy as np
from annotate_view import load, stretch, ROT_TO_IR
plant,cam=sys.argv[1:3]; u0,v0,u1,v1,zoom,step=map(int,sys.argv[3:9]); out=sys.argv[9]
blur=float(sys.argv[10]) if len(sys.argv)>10 else 0
img=load(plant,cam)
H,W=img.shape[:2]; u0,v0,u1,v1=max(u0,0),max(v0,0),min(u1,W),min(v1,H)
sub=img[v0:v1,u0:u1]
if blur>0 and sub.ndim==2: sub=cv2.GaussianBlur(sub,(0,0),blur)
rgb=stretch(cam,sub,True)
Vg,Ug=np.mgrid[v0:v1,u0:u1]
k=ROT_TO_IR.get(cam,0)
rgb=np.ascontiguousarray(np.rot90(rgb,k)); Ug=np.rot90(Ug,k); Vg=np.rot90(Vg,k)
big=cv2.resize(rgb,None,fx=zoom,fy=zoom,interpolation=cv2.INTER_NEAREST)
M=40
can=np.full((big.shape[0]+M,big.shape[1]+M,3),255,np.uint8); can[M:,M:]=big
col_is_u=np.all(Ug[:,0]==Ug[0,0])
cols=Ug[0,:] if col_is_u else Vg[0,:]; rows=Vg[:,0] if col_is_u else Ug[:,0]
for i,c in enumerate(cols):
    if c%step==0:
        X=M+int((i+0.5)*zoom); cv2.line(can,(X,M),(X,can.shape[0]),(0,180,0),1)
        cv2.putText(can,str(c),(X-10,M-8-10*((c//step)%2)),cv2.FONT_HERSHEY_PLAIN,0.8,(0,0,0),1)
for i,r in enumerate(rows):
    if r%step==0:
        Y=M+int((i+0.5)*zoom); cv2.line(can,(M,Y),(can.shape[1],Y),(0,180,0),1)
        cv2.putText(can,str(r),(1,Y+4),cv2.FONT_HERSHEY_PLAIN,0.8,(0,0,0),1)
cv2.putText(can,f"{plant} {cam} cols:{'u' if col_is_u else 'v'} rows:{'v' if col_is_u else 'u'}",(2,10),cv2.FONT_HERSHEY_PLAIN,0.8,(200,0,0),1)
cv2.imwrite(out,can)
