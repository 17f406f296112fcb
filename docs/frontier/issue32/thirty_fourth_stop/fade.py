import csv,sys,numpy as np
from collections import defaultdict
d=sys.argv[1]; setting=sys.argv[2]; scene=sys.argv[3]
M=defaultdict(lambda: np.zeros(6)); M2=defaultdict(lambda: np.zeros(6)); G=defaultdict(lambda: np.zeros(6))
ws=[]
for r in csv.DictReader(open(d+'/contacts.csv')):
  if r['scene']!=scene or r['setting']!=setting: continue
  p=int(r['pose_id']); m=np.array([float(r[k]) for k in ['fx','fy','fz','tx','ty','tz']]); w=np.array([float(r[k]) for k in ['fx_gt','fy_gt','fz_gt','tx_gt','ty_gt','tz_gt']])
  k=float(r['stiffness_n_per_m']); dl=float(r['delta_m'])
  wt=np.linalg.norm(m[:3])/(k*dl) if dl>0 else 1
  ws.append(wt)
  M[p]+=m; M2[p]+= (w if wt<0.5 else m)
for r in csv.DictReader(open(d+'/patches.csv')):
  if r['scene']!=scene: continue
  p=int(r['pose_id']); G[p]+=np.array([float(r[k]) for k in ['fx_gt','fy_gt','fz_gt','tx_gt','ty_gt','tz_gt']])
def err(M):
  fe=fg=te=tg=0
  for p in G:
    fe+=np.sum((M[p][:3]-G[p][:3])**2); fg+=np.sum(G[p][:3]**2); te+=np.sum((M[p][3:]-G[p][3:])**2); tg+=np.sum(G[p][3:]**2)
  return np.sqrt(fe/fg),np.sqrt(te/tg)
ws=np.array(ws); print('contacts',len(ws),'weight<0.5:',np.sum(ws<0.5),'weight<0.95',np.sum(ws<0.95), 'p10,50',np.percentile(ws,[10,50]))
print('as is F %.4f T %.4f'%err(M)); print('faded contacts given their window truth: F %.4f T %.4f'%err(M2))
