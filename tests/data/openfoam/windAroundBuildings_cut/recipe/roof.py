# ruff: noqa
# Recipe script as run for tests/data/openfoam (paths are those of the run; adapt them).
import numpy as np

v=[];f=[]
for l in open('constant/triSurface/buildings.obj'):
    if l.startswith('v '): v.append([float(x) for x in l.split()[1:4]])
    elif l.startswith('f '): f.append([int(x.split('/')[0])-1 for x in l.split()[1:4]])
v=np.array(v);f=np.array(f); t=v[f]
z=t[:,:,2]; flat=(np.ptp(z,1)<1e-6)&(z[:,0]>0); T=t[flat]
def top(x,y):
    a,b,c=T[:,0,:2],T[:,1,:2],T[:,2,:2]
    def cr(p,q,r): return (q[:,0]-p[:,0])*(r[...,1]-p[:,1])-(q[:,1]-p[:,1])*(r[...,0]-p[:,0])
    P=np.array([[x,y]])
    d1=cr(a,b,P);d2=cr(b,c,P);d3=cr(c,a,P)
    ins=((d1>=0)&(d2>=0)&(d3>=0))|((d1<=0)&(d2<=0)&(d3<=0))
    return T[ins,0,2].max() if ins.any() else 0.0
best=[]
for x in np.arange(20,230,4.0):
    for y in np.arange(30,150,4.0):
        h=top(x,y)
        if h<25: continue
        ok=all(abs(top(x+dx,y+dy)-h)<1e-6 for dx in (-5,0,5) for dy in (-5,0,5))
        if ok: best.append((h,x,y))
best.sort()
print(best[-15:], len(best))
print('street candidates')
for x in np.arange(20,230,4.0):
    for y in np.arange(30,150,4.0):
        if all(top(x+dx,y+dy)==0 for dx in (-12,-6,0,6,12) for dy in (-12,-6,0,6,12)):
            print(x,y, end='; ')
