#!/usr/bin/python3
"""Per deploy/run-loopback run: the compact contact models' and compact tool states' rates
(summary.json transport.streams) and the bytes a model datagram took.
Usage: bandwidth.py RUN_DIR..."""
import json,sys,os,glob
for d in sys.argv[1:]:
    try: s=json.load(open(os.path.join(d,'summary.json')))
    except Exception as e: print(d,'no summary'); continue
    st=s['transport']['streams']
    cm=st.get('compact_contact_model',{}); ts=st.get('compact_tool_state',{})
    print(f"{os.path.basename(d):40s} models {cm.get('packets_per_s',0):6.1f}/s {cm.get('kbit_per_s',0):6.1f} kbit/s  B/model {cm.get('bytes_received',0)/max(cm.get('received',1),1):6.1f}  tool states {ts.get('packets_per_s',0):5.1f}/s {ts.get('kbit_per_s',0):5.1f} kbit/s")
