#!/usr/bin/env python3
"""Per pose: the method's torque against the pipeline truth with the 1 um tilt lift (NEW) and with the
texel tilt (OLD), one scene, setting default. Usage: pose_torque.py SCENE NEW_DIR OLD_DIR"""
import csv, collections, math, sys
scene, new, old = sys.argv[1:4]
def truth(d):
    T = collections.defaultdict(lambda: [0.0, 0.0, 0.0])
    for r in csv.DictReader(open(d + '/patches.csv')):
        if r['scene'] != scene: continue
        for i, c in enumerate('xyz'): T[int(r['pose_id'])][i] += float(r['t' + c + '_gt']) * float(r['share'])
    return T
M = collections.defaultdict(lambda: [0.0, 0.0, 0.0])
for r in csv.DictReader(open(new + '/contacts.csv')):
    if r['scene'] != scene or r['setting'] != 'default': continue
    for i, c in enumerate('xyz'): M[int(r['pose_id'])][i] += float(r['t' + c])
Tn, To = truth(new), truth(old)
def rel(T):
    num = sum(math.dist(M[k], T[k]) ** 2 for k in M); den = sum(math.hypot(*T[k]) ** 2 for k in M)
    return math.sqrt(num / den)
print(f'{scene}: torque err vs new truth {rel(Tn):.3f}, vs old truth {rel(To):.3f}; |tau| rms new {math.sqrt(sum(math.hypot(*Tn[k])**2 for k in M)/len(M)):.4f} old {math.sqrt(sum(math.hypot(*To[k])**2 for k in M)/len(M)):.4f}')
# which is closer to the method, pose by pose
closer_new = sum(1 for k in M if math.dist(M[k], Tn[k]) < math.dist(M[k], To[k]))
print(f'poses where the method is closer to the new truth: {closer_new} of {len(M)}')
ch = sorted(M, key=lambda k: -math.dist(Tn[k], To[k]))
for k in ch[:8]:
    f = lambda v: '(' + ', '.join(f'{x*1e3:6.1f}' for x in v) + ')'
    print(k, 'method', f(M[k]), 'new', f(Tn[k]), 'old', f(To[k]), 'mN·m')
