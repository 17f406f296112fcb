# Torque of the pipeline truth against the volume truth (-grad V scaled to the pipeline truth's
# |F|), and the method against each, per scene: how well the measure itself is defined.
import csv,sys,numpy as np
from collections import defaultdict
d=sys.argv[1]; setting=sys.argv[2] if len(sys.argv)>2 else 'default'
M=defaultdict(lambda: defaultdict(lambda: np.zeros(6))); G=defaultdict(lambda: defaultdict(lambda: np.zeros(6))); V=defaultdict(lambda: defaultdict(lambda: np.zeros(6)))
for r in csv.DictReader(open(d+'/contacts.csv')):
  if r['setting']!=setting: continue
  M[r['scene']][int(r['pose_id'])]+=np.array([float(r[k]) for k in ['fx','fy','fz','tx','ty','tz']])
for r in csv.DictReader(open(d+'/patches.csv')):
  s=r['scene']; p=int(r['pose_id'])
  G[s][p]+=np.array([float(r[k]) for k in ['fx_gt','fy_gt','fz_gt','tx_gt','ty_gt','tz_gt']])
  V[s][p]+=np.array([float(r[k]) for k in ['dV_dx','dV_dy','dV_dz','dV_dthx','dV_dthy','dV_dthz']])
def rel(A,B,sl):
  e=sum(np.sum((A[p][sl]-B[p][sl])**2) for p in B); g=sum(np.sum(B[p][sl]**2) for p in B); return np.sqrt(e/g) if g>0 else float('nan')
print('scene  poses | torque rel RMS: volume vs pipeline | method vs pipeline | method vs volume || force: volume dir vs pipeline | method vs volume')
for s in G:
  W={}
  for p in G[s]:
    v=V[s][p]; fn=np.linalg.norm(v[:3])
    if fn<=0: continue
    c=np.linalg.norm(G[s][p][:3])/fn; W[p]=-c*v
  poses=[p for p in W]
  Gp={p:G[s][p] for p in poses}; Mp={p:M[s][p] for p in poses}
  print('%-13s %3d | %6.1f %% | %6.1f %% | %6.1f %% || %6.1f %% | %6.1f %%'%(s,len(poses),100*rel(W,Gp,slice(3,6)),100*rel(Mp,Gp,slice(3,6)),100*rel(Mp,W,slice(3,6)),100*rel(W,Gp,slice(0,3)),100*rel(Mp,W,slice(0,3))))
