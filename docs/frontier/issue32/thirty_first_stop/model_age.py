#!/usr/bin/env python3
"""Model age the operator rendered (trace.csv, the rotate phase) and the remote step in contact
(remote_steps.csv, steps with contacts) of deploy/run-loopback runs.
Usage: model_age.py RUN_DIR [RUN_DIR ...] (numpy)."""
import csv,sys,numpy as np
for d in sys.argv[1:]:
    R=list(csv.DictReader(open(d+'/trace.csv')))
    ph=[r for r in R if r.get('phase','')=='rotate'] or R
    age=np.array([float(r['model_age_ms']) for r in ph if r['model_age_ms'] not in ('','nan')])
    S=list(csv.DictReader(open(d+'/remote_steps.csv')))
    st=np.array([float(s['total_us']) for s in S if int(s['contacts'])>0])
    print(f"{d}: model age p50 {np.percentile(age,50):.1f} ms p99 {np.percentile(age,99):.1f} ms; remote step in contact p50 {np.percentile(st,50):.0f} us p99 {np.percentile(st,99):.0f} us ({len(st)} steps)")
