import csv,math,sys,collections
import numpy as np
d=sys.argv[1]; setting=sys.argv[2] if len(sys.argv)>2 else 'default'
C=collections.defaultdict(list); P=collections.defaultdict(list)
for r in csv.DictReader(open(d+'/contacts.csv')):
    if r['setting']==setting: C[(r['scene'],r['pose_id'])].append(r)
for r in csv.DictReader(open(d+'/patches.csv')): P[(r['scene'],r['pose_id'])].append(r)
for scene in ('fig75','fig76','fig77','hammer_torus'):
    angs=[];ratio=[]
    for key,ps in P.items():
        if key[0]!=scene: continue
        for p in ps:
            n=np.array([float(p['window_n'+a]) for a in 'xyz']); c=np.array([float(p['window_c'+a]) for a in 'xyz'])
            best=None
            for r in C.get(key,[]):
                if not float(r['delta_m'])>0: continue
                m=np.array([float(r['window_n'+a]) for a in 'xyz']); cc=np.array([float(r['window_c'+a]) for a in 'xyz'])
                dist=np.linalg.norm(cc-c)
                if best is None or dist<best[0]: best=(dist,math.degrees(math.acos(min(1,abs(n@m)))))
            if best and best[0]<0.02: angs.append(best[1])
    a=np.array(angs)
    if len(a): print(scene,len(a),'angle to nearest touching window p25/50/75/90',np.percentile(a,[25,50,75,90]).round(1))
