#!/usr/bin/env python3
"""|F| of the device and of the simulated tool's contact along deadband_lockstep traces: steps
and one-tick spikes (a tick off both neighbours by > 0.2 N the same way) above 0.2 N, and a plot.
Usage: force_steps.py OUT.png TRACE.csv=LABEL [TRACE.csv=LABEL ...] (numpy, matplotlib)."""
import csv, sys, numpy as np
import matplotlib; matplotlib.use('Agg'); import matplotlib.pyplot as plt
out=sys.argv[1]; specs=sys.argv[2:]
fig,ax=plt.subplots(len(specs),1,figsize=(11,2.6*len(specs)),sharex=True)
for a,spec in zip(np.atleast_1d(ax),specs):
    f,label=spec.split('=')
    R=list(csv.DictReader(open(f)))
    t=np.array([float(r['t_s']) for r in R])
    for kind in ('device','contact'):
        F=np.linalg.norm(np.array([[float(r[f'{kind}_f'+k]) for k in 'xyz'] for r in R]),axis=1)
        # one-tick spikes: a tick off both neighbours by > 0.2 N in the same direction
        d1=F[1:-1]-F[:-2]; d2=F[1:-1]-F[2:]
        sp=np.sum((np.abs(d1)>0.2)&(np.abs(d2)>0.2)&(np.sign(d1)==np.sign(d2)))
        st=np.sum(np.abs(np.diff(F))>0.2)
        print(f"{label:28s} {kind:7s} steps>0.2N {st:4d}  one-tick spikes>0.2N {sp:3d}  max |dF| {np.abs(np.diff(F)).max():.3f} N")
        a.plot(t,F,lw=0.7,label=f'{kind} |F|')
    a.set_title(label,fontsize=9); a.legend(fontsize=7); a.set_ylabel('N')
a.set_xlabel('t (s)'); fig.tight_layout(); fig.savefig(out,dpi=90)
