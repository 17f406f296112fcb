import csv,sys,numpy as np
from collections import defaultdict
d=sys.argv[1]; scene=sys.argv[2]; settings=sys.argv[3].split(',')
G=defaultdict(lambda: np.zeros(6))
for r in csv.DictReader(open(d+'/patches.csv')):
  if r['scene']==scene: G[int(r['pose_id'])]+=np.array([float(r[k]) for k in ['fx_gt','fy_gt','fz_gt','tx_gt','ty_gt','tz_gt']])
M={s:defaultdict(lambda: np.zeros(6)) for s in settings}
for r in csv.DictReader(open(d+'/contacts.csv')):
  if r['scene']==scene and r['setting'] in M: M[r['setting']][int(r['pose_id'])]+=np.array([float(r[k]) for k in ['fx','fy','fz','tx','ty','tz']])
poses=sorted(set(G)|set().union(*[set(m) for m in M.values()]))
n=max(poses)+1
def series(D): return np.array([D[p] if p in D else np.zeros(6) for p in range(n)])
def report(name,S):
  j=np.linalg.norm(np.diff(S[:,:3],axis=0),axis=1)
  print('%-40s |dF| between consecutive poses: p50 %.3f p90 %.3f p99 %.3f max %.3f  >0.2N: %d  >0.1N: %d'%(name,*np.percentile(j,[50,90,99]),j.max(),(j>0.2).sum(),(j>0.1).sum()))
Gs=series(G); report('truth',Gs)
for s in settings:
  S=series(M[s]); report(s,S); e=np.sqrt(np.sum((S[:,:3]-Gs[:,:3])**2)/np.sum(Gs[:,:3]**2)); print('   force rel rms vs truth %.3f'%e)
