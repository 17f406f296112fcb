import csv,sys,numpy as np
from collections import defaultdict
d=sys.argv[1]; setting=sys.argv[2]; scene=sys.argv[3]
M=defaultdict(lambda: np.zeros(6)); G=defaultdict(lambda: np.zeros(6)); nc=defaultdict(int); npch=defaultdict(int)
for r in csv.DictReader(open(d+'/contacts.csv')):
  if r['scene']!=scene or r['setting']!=setting: continue
  p=int(r['pose_id']); M[p]+=np.array([float(r[k]) for k in ['fx','fy','fz','tx','ty','tz']]); nc[p]+=1
for r in csv.DictReader(open(d+'/patches.csv')):
  if r['scene']!=scene: continue
  p=int(r['pose_id']); G[p]+=np.array([float(r[k]) for k in ['fx_gt','fy_gt','fz_gt','tx_gt','ty_gt','tz_gt']]); npch[p]+=1
poses=sorted(set(M)|set(G))
fe=fg=te=tg=0
rows=[]
for p in poses:
  m=M[p]; g=G[p]
  fe+=np.sum((m[:3]-g[:3])**2); fg+=np.sum(g[:3]**2); te+=np.sum((m[3:]-g[3:])**2); tg+=np.sum(g[3:]**2)
  rows.append((np.sum((m[3:]-g[3:])**2), np.sum((m[:3]-g[:3])**2), p, m, g))
print('force rel rms %.4f torque %.4f'%(np.sqrt(fe/fg),np.sqrt(te/tg)))
np.set_printoptions(precision=4,suppress=True)
key=1 if (len(sys.argv)>4 and sys.argv[4]=='f') else 0
rows.sort(key=lambda r:-r[key])
for r in rows[:int(sys.argv[5]) if len(sys.argv)>5 else 12]:
  print(r[2], 'nc',nc[r[2]],'np',npch[r[2]],'share T %.3f F %.3f'%(r[0]/te, r[1]/fe)); print('  m',r[3]); print('  g',r[4])
E=np.zeros(6); Gs=np.zeros(6)
for p in poses:
  E+=(M[p]-G[p])**2; Gs+=G[p]**2
print('per-axis error sum sq share F', E[:3]/E[:3].sum(), 'T', E[3:]/E[3:].sum())
print('per-axis truth sum sq F', Gs[:3], 'T', Gs[3:])
