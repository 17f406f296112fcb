#!/usr/bin/env python3
"""Force-error breakdown of a frontier run (contacts.csv, patches.csv): per pose the summed
method force against the pipeline truth, its direction and magnitude shares, the poses where the
method gives no force, and for those the windows near each truth patch. Usage:
fig77_breakdown.py FRONTIER_OUT [SETTING]. Needs numpy."""
import csv, collections, math, sys
import numpy as np
d=sys.argv[1]; setting=sys.argv[2] if len(sys.argv)>2 else 'default'
C=[r for r in csv.DictReader(open(d+'/contacts.csv')) if r['setting']==setting]
P=list(csv.DictReader(open(d+'/patches.csv')))
Fm=collections.defaultdict(lambda: np.zeros(3)); Fg=collections.defaultdict(lambda: np.zeros(3))
win=collections.defaultdict(list); pat=collections.defaultdict(list)
for r in C:
  F=np.array([float(r[k]) for k in ('fx','fy','fz')]); Fm[r['pose_id']]+=F
  win[r['pose_id']].append((np.array([float(r[k]) for k in ('window_cx','window_cy','window_cz')]), np.array([float(r[k]) for k in ('window_nx','window_ny','window_nz')]), float(r['delta_m']), F))
for r in P:
  F=np.array([float(r[k]) for k in ('fx_gt','fy_gt','fz_gt')]); Fg[r['pose_id']]+=F
  pat[r['pose_id']].append((np.array([float(r[k]) for k in ('window_cx','window_cy','window_cz')]), np.array([float(r[k]) for k in ('window_nx','window_ny','window_nz')]), float(r['delta_gt_m']), F))
ang=[];ratio=[];err=[];nang=[];dr=[];fang=[]
for p in Fg:
  a,b=Fm[p],Fg[p]
  if np.linalg.norm(b)<1e-9: continue
  err.append(np.linalg.norm(a-b)**2); ratio.append(np.linalg.norm(a)/np.linalg.norm(b))
  if np.linalg.norm(a)>1e-9: ang.append(math.degrees(math.acos(np.clip(a@b/np.linalg.norm(a)/np.linalg.norm(b),-1,1))))
  for c,n,dg,Fp in pat[p]:
    cand=[w for w in win[p] if w[2]>0]
    if not cand: continue
    w=min(cand,key=lambda w:np.linalg.norm(w[0]-c))
    nang.append(math.degrees(math.acos(np.clip(w[1]@n,-1,1)))); dr.append(w[2]/dg if dg>0 else np.nan)
    if np.linalg.norm(w[3])>0 and np.linalg.norm(Fp)>0: fang.append(math.degrees(math.acos(np.clip(w[3]@Fp/np.linalg.norm(w[3])/np.linalg.norm(Fp),-1,1))))
tot=sum(np.linalg.norm(Fg[p])**2 for p in Fg)
print(setting,'poses',len(err),'rel rms %.3f'%math.sqrt(sum(err)/tot),'|F|/|Fgt| p50 %.2f p25 %.2f p75 %.2f'%tuple(np.percentile(ratio,[50,25,75])),'F angle p50 %.1f p90 %.1f'%tuple(np.percentile(ang,[50,90])))
print(' nearest window normal vs truth normal p50 %.1f p90 %.1f; delta ratio p50 %.2f; window-force vs patch-force angle p50 %.1f'%(np.percentile(nang,50),np.percentile(nang,90),np.nanpercentile(dr,50),np.percentile(fang,50)))
# error if method force had right magnitude but its direction; and right direction with its magnitude
e_dir=sum(np.linalg.norm(Fm[p]/max(np.linalg.norm(Fm[p]),1e-12)*np.linalg.norm(Fg[p])-Fg[p])**2 for p in Fg if np.linalg.norm(Fm[p])>0)
e_mag=sum((np.linalg.norm(Fm[p])-np.linalg.norm(Fg[p]))**2 for p in Fg)
print(' error from direction only %.3f, from magnitude only %.3f'%(math.sqrt(e_dir/tot),math.sqrt(e_mag/tot)))
print('--- low poses')
lows=sorted([p for p in Fg if np.linalg.norm(Fg[p])>0], key=lambda p: np.linalg.norm(Fm[p])/np.linalg.norm(Fg[p]))[:12]
for p in lows:
  print(p,'|F| %.2f gt %.2f'%(np.linalg.norm(Fm[p]),np.linalg.norm(Fg[p])),'windows',[(round(w[2]*1e6,1),np.round(w[1],2).tolist(),round(float(np.linalg.norm(w[3])),2)) for w in win[p]][:8],'truth',[(round(q[2]*1e6,1),np.round(q[1],2).tolist(),round(float(np.linalg.norm(q[3])),2), np.round(q[0]*1e3,1).tolist()) for q in pat[p]])
  for w in win[p]:
    if w[2]>0: print('    win centre',np.round(w[0]*1e3,1).tolist())
z=[p for p in Fg if np.linalg.norm(Fm[p])<1e-9 and np.linalg.norm(Fg[p])>0]
print('zero-force poses',len(z),'share of squared error %.2f'%(sum(np.linalg.norm(Fg[p])**2 for p in z)/sum(err)))
# among them: windows with -inf vs finite negative
ninf=sum(1 for p in z for w in win[p] if w[2]==-np.inf); nneg=sum(1 for p in z for w in win[p] if np.isfinite(w[2]) and w[2]<=0)
print(' their windows: -inf',ninf,' finite<=0',nneg)
# nearest window to truth patch in zero poses: normal angle & delta
for p in z[:40]:
  for c,n,dg,Fp in pat[p]:
    w=min(win[p],key=lambda w:np.linalg.norm(w[0]-c)) if win[p] else None
    if w is None: print(p,'no window'); continue
    best=max(win[p], key=lambda w: w[1]@n)
    print(p,'nearest: dist %.1f mm ang %.0f delta %s | best-aligned: ang %.0f delta %s dist %.1f | truth delta %.0f'%(np.linalg.norm(w[0]-c)*1e3, math.degrees(math.acos(np.clip(w[1]@n,-1,1))), round(w[2]*1e6,1), math.degrees(math.acos(np.clip(best[1]@n,-1,1))), round(best[2]*1e6,1), np.linalg.norm(best[0]-c)*1e3, dg*1e6))
