import csv,sys,numpy as np, matplotlib; matplotlib.use('Agg'); import matplotlib.pyplot as plt
out=sys.argv[1]; t0,t1=float(sys.argv[2]),float(sys.argv[3]); files=sys.argv[4:]
fig,ax=plt.subplots(5,1,figsize=(14,14),sharex=True)
for f in files:
  path,label=f.split('=')
  R=list(csv.DictReader(open(path)))
  t=np.array([float(r['t_s']) for r in R]); m=(t>=t0)&(t<=t1)
  g=lambda k: np.array([float(r[k]) for r in R])[m]
  ax[0].plot(t[m],g('tool_y')*1e3,label=label); ax[1].plot(t[m],g('tool_z')*1e3,label=label)
  ax[2].plot(t[m],g('contact_fy'),label=label); ax[3].plot(t[m],g('contact_fz'),label=label); ax[4].plot(t[m],g('device_fy'),label=label)
for a,l in zip(ax,['tool y (mm)','tool z (mm)','contact Fy (N)','contact Fz (N)','device Fy (N)']): a.set_ylabel(l); a.grid(alpha=.3)
ax[0].legend(); ax[-1].set_xlabel('t (s)'); plt.tight_layout(); plt.savefig(out,dpi=80)
