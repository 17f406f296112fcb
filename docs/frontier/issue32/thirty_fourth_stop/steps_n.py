import csv,sys,numpy as np
for f in sys.argv[1:]:
  R=list(csv.DictReader(open(f)))
  cf=np.array([[float(r['contact_f'+a]) for a in 'xyz'] for r in R]); n=np.array([int(r['contacts']) for r in R]); arr=np.array([int(r['model_arrived']) for r in R])
  P=np.array([[float(r[k]) for k in ['tool_x','tool_y','tool_z','tool_rx','tool_ry','tool_rz']] for r in R])
  d=np.linalg.norm(np.diff(cf,axis=0),axis=1); idx=np.where(d>0.2)[0]
  chg=(n[1:]!=n[:-1])
  print(f,'steps',len(idx),'with count change',int(chg[idx].sum()),'count changes total',int(chg.sum()),'on arrival',int(arr[1:][idx].sum()))
  v=np.diff(P,axis=0); print('  tool motion per tick RMS: xyz um',np.sqrt((v[:,:3]**2).mean(0))*1e6,' rot mrad',np.sqrt((v[:,3:]**2).mean(0))*1e3)
