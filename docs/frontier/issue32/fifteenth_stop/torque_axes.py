#!/usr/bin/python3
"""Per scene of a speed_error_frontier output (contacts.csv, patches.csv): the pose-summed torque of
the method (SETTING, default "default") against the pipeline truth (each patch weighed by its share),
per axis: RMS of each, the RMS error, correlation and least-squares slope (method on truth), and the
poses carrying the most squared error.

Usage: torque_axes.py FRONTIER_DIR [SETTING]"""
import csv, numpy as np, sys, collections
d=sys.argv[1]; setting=sys.argv[2] if len(sys.argv)>2 else 'default'
C=list(csv.DictReader(open(d+'/contacts.csv'))); P=list(csv.DictReader(open(d+'/patches.csv')))
for sc in ['fig75','fig76','fig77','hammer_torus']:
  m=collections.defaultdict(lambda: np.zeros(6)); g=collections.defaultdict(lambda: np.zeros(6))
  cnt=collections.Counter(); pc=collections.Counter()
  for r in C:
    if r['scene']!=sc or r['setting']!=setting: continue
    m[r['pose_id']]+=np.array([float(r[k]) for k in ['fx','fy','fz','tx','ty','tz']]); cnt[r['pose_id']]+=1
  for r in P:
    if r['scene']!=sc: continue
    g[r['pose_id']]+=float(r['share'])*np.array([float(r[k]) for k in ['fx_gt','fy_gt','fz_gt','tx_gt','ty_gt','tz_gt']]); pc[r['pose_id']]+=1
  ids=sorted(set(m)|set(g))
  if not ids: continue
  M=np.array([m[i] for i in ids]); G=np.array([g[i] for i in ids])
  F,Fg,T,Tg=M[:,:3],G[:,:3],M[:,3:],G[:,3:]
  print(sc,'poses',len(ids),'force err %.3f torque err %.3f'%(np.sqrt(((F-Fg)**2).sum()/(Fg**2).sum()),np.sqrt(((T-Tg)**2).sum()/(Tg**2).sum())))
  for i,n in enumerate('xyz'):
    print('  t'+n,'rms gt %.4f rms m %.4f rms err %.4f corr %.3f slope %.3f'%(np.sqrt((Tg[:,i]**2).mean()),np.sqrt((T[:,i]**2).mean()),np.sqrt(((T-Tg)[:,i]**2).mean()),np.corrcoef(T[:,i],Tg[:,i])[0,1], (T[:,i]*Tg[:,i]).sum()/(Tg[:,i]**2).sum()))
  e=((T-Tg)**2).sum(1); o=np.argsort(-e); print('  top10 share %.2f top30 %.2f'%(e[o[:10]].sum()/e.sum(),e[o[:30]].sum()/e.sum()))
  for k in o[:5]:
    print('   pose',ids[k],'T',np.round(T[k],4),'Tg',np.round(Tg[k],4),'F',np.round(F[k],2),'Fg',np.round(Fg[k],2),'ncont',cnt[ids[k]],'npatch',pc[ids[k]])
