# The pipeline truth against itself under another of its own settings (two frontier runs on the
# same poses): relative RMS of the per-pose wrench, force and torque, and of the method against each.
import csv,sys,numpy as np
from collections import defaultdict
def load(d):
  G=defaultdict(lambda: defaultdict(lambda: np.zeros(6))); P={}
  for r in csv.DictReader(open(d+'/patches.csv')):
    s=r['scene']; p=int(r['pose_id'])
    G[s][p]+=np.array([float(r[k]) for k in ['fx_gt','fy_gt','fz_gt','tx_gt','ty_gt','tz_gt']])
    P[(s,p)]=tuple(round(float(r[k]),9) for k in ['tool_px','tool_py','tool_pz','tool_qw'])
  M=defaultdict(lambda: defaultdict(lambda: np.zeros(6)))
  for r in csv.DictReader(open(d+'/contacts.csv')):
    if r['setting']!='default': continue
    M[r['scene']][int(r['pose_id'])]+=np.array([float(r[k]) for k in ['fx','fy','fz','tx','ty','tz']])
  return G,P,M
def rel(A,B,sl,poses):
  e=sum(np.sum((A[p][sl]-B[p][sl])**2) for p in poses); g=sum(np.sum(B[p][sl]**2) for p in poses); return np.sqrt(e/g)
A,PA,MA=load(sys.argv[1]); B,PB,MB=load(sys.argv[2])
print('scene poses | B vs A truth: force, torque | method vs A: F, T | method vs B: F, T')
for s in A:
  poses=sorted(set(A[s])|set(B[s]))
  same=sum(1 for p in poses if PA.get((s,p))==PB.get((s,p)))
  print('%-12s %3d (same pose %3d) | %5.1f %% %5.1f %% | %5.1f %% %5.1f %% | %5.1f %% %5.1f %%'%(s,len(poses),same,
    100*rel(B[s],A[s],slice(0,3),poses),100*rel(B[s],A[s],slice(3,6),poses),
    100*rel(MA[s],A[s],slice(0,3),poses),100*rel(MA[s],A[s],slice(3,6),poses),
    100*rel(MA[s],B[s],slice(0,3),poses),100*rel(MA[s],B[s],slice(3,6),poses)))
