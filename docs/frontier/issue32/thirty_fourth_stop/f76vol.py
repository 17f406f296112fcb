import csv,sys,numpy as np
from collections import defaultdict
d=sys.argv[1]; setting=sys.argv[2]; scene=sys.argv[3]
M=defaultdict(lambda: np.zeros(6)); W=defaultdict(lambda: np.zeros(6)); G=defaultdict(lambda: np.zeros(6)); V=defaultdict(lambda: np.zeros(6)); Q={}
for r in csv.DictReader(open(d+'/contacts.csv')):
  if r['scene']!=scene or r['setting']!=setting: continue
  p=int(r['pose_id']); M[p]+=np.array([float(r[k]) for k in ['fx','fy','fz','tx','ty','tz']]); W[p]+=np.array([float(r[k]) for k in ['fx_gt','fy_gt','fz_gt','tx_gt','ty_gt','tz_gt']])
  Q[p]=[float(r[k]) for k in ['tool_qw','tool_qx','tool_qy','tool_qz']]
for r in csv.DictReader(open(d+'/patches.csv')):
  if r['scene']!=scene: continue
  p=int(r['pose_id']); G[p]+=np.array([float(r[k]) for k in ['fx_gt','fy_gt','fz_gt','tx_gt','ty_gt','tz_gt']]); V[p]+=np.array([float(r[k]) for k in ['dV_dx','dV_dy','dV_dz','dV_dthx','dV_dthy','dV_dthz']])
print('pose  thz(mrad)  arms (mm) tau/Fz for z, x, y: method | own | pipeline | volume(-dV/dth / -dV/dz)')
E=defaultdict(list)
for p in sorted(M)[:: int(sys.argv[4]) if len(sys.argv)>4 else 1]:
  q=Q[p]; thz=2*q[3]*np.sign(q[0])*1000
  row=[]
  for name,X in [('m',M[p]),('w',W[p]),('g',G[p])]:
    row.append(X[3:]/X[2]*1000)
  v=V[p]; vol=(v[3:]/v[2])*1000 if v[2]!=0 else np.zeros(3)
  row.append(vol)
  for i,name in enumerate('mwgv'): E[name].append(row[i])
  print('%3d %6.1f  z: %6.2f %6.2f %6.2f %6.2f | x: %6.2f %6.2f %6.2f %6.2f | y: %6.2f %6.2f %6.2f %6.2f'%(p,thz,*[r[2] for r in row],*[r[0] for r in row],*[r[1] for r in row]))
for name in 'mwg':
  e=np.array(E[name])-np.array(E['v']); print(name,'rms arm diff vs volume (mm) x,y,z', np.sqrt(np.mean(e**2,axis=0)))
