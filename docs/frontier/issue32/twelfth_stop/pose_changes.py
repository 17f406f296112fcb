#!/usr/bin/env python3
"""Per pose of a frontier run, how a second setting changes the squared pipeline force error
against a first (summed over the pose's contacts against its truth patches): the total change,
the six poses it helped most and the eight it hurt most, with each setting's contact depths and
the truth's patch depths (µm).
Usage: pose_changes.py FRONTIER_DIR SCENE SETTING_A SETTING_B (no numpy needed)."""
import csv,collections,math,sys
d,scene,s1,s2=sys.argv[1:5]
def load(st):
    C=collections.defaultdict(list)
    for r in csv.DictReader(open(f'{d}/contacts.csv')):
        if r['scene']==scene and r['setting']==st: C[int(r['pose_id'])].append(r)
    return C
P=collections.defaultdict(list)
for r in csv.DictReader(open(f'{d}/patches.csv')):
    if r['scene']==scene: P[int(r['pose_id'])].append(r)
D=load(s1); X=load(s2)
def F(rows,k=('fx','fy','fz')): return [sum(float(c[x]) for c in rows) for x in k]
L=[]
for p in sorted(P):
    ft=F(P[p],('fx_gt','fy_gt','fz_gt'))
    ed=math.dist(F(D[p]),ft)**2; ex=math.dist(F(X[p]),ft)**2
    L.append((ex-ed,p,math.sqrt(ed),math.sqrt(ex),math.hypot(*ft),[round(float(c['delta_m'])*1e6) for c in D[p] if float(c['delta_m'])>-1e-3],[round(float(c['delta_m'])*1e6) for c in X[p] if float(c['delta_m'])>-1e-3],[round(float(t['delta_gt_m'])*1e6) for t in P[p]]))
L.sort()
print("sum sq change", sum(x[0] for x in L))
for x in L[:6]+L[-8:]: print(x[1], 'err %.2f -> %.2f |Ft| %.2f'%(x[2],x[3],x[4]), 'δ', x[5], '->', x[6], 'truth', x[7])
