import csv,sys
for r in csv.DictReader(open(sys.argv[1]+'/frontier.csv')):
  print(f"{r['scene']:13s} {r['setting']:30s} F {float(r['pipeline_force_rel_rms'])*100:5.1f} T {float(r['pipeline_torque_rel_rms'])*100:5.1f} d50 {float(r['delta_err_p50_um']):6.1f} tex50 {float(r['texture_p50_us']):7.0f} nf {r['poses_truth_without_force']:>3s} miss {r['contacts_missed']:>4s}/{r['windows']} c {float(r['contacts_mean']):.2f} vdir50 {r['volume_dir_p50_deg']}")
