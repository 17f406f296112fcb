#!/usr/bin/env python3
"""Checks that the remote node waited on its socket instead of stepping when a step would see
nothing new (issue 33). Usage: idle_loopback_check.py RUN_DIR [still|contact]
- still (default): a run whose hand held still in free space (tests/data/still_hand.csv). Once
  the tool has settled (the second half of the node's steps in time), every step answers a tool
  state that arrived (remote_steps.csv `cause` 2) or sends a model the model period held (4), and
  no tool state is stepped more than twice; the loop passes that waited are counted, and the
  operator never felt a contact. While the tool settles it may pass near the gear, where the
  extrapolated pose is stepped as it moves (cause 5): those steps are reported, not limited.
- contact: a fig75 run without deadband (--deadband 0): tool states come every tick at an
  unchanged pose in between, so over the whole run each is stepped once, and once more at most
  when its model was held by the model period (stepped again at the period's end, not in a
  loop); the operator felt contact.
Both: the causes in remote_steps.csv and remote_summary.json's steps_by_cause agree (two
records of one decision). No figure per second is asserted: the CPU share is reported
(remote_summary.json cpu_share_since_first_step), not tested."""
import collections
import csv
import json
import sys

CAUSES = {1: "first", 2: "tool_state", 3: "scene_moves", 4: "model_period_end", 5: "pose_moved"}
out = sys.argv[1]
mode = sys.argv[2] if len(sys.argv) > 2 else "still"
remote = json.load(open(f"{out}/remote_summary.json"))
t = remote["transport"]
# Tool states come as compact_tool_state (the default encoding) or tool_state.
states = sum(t["streams"].get(name, {}).get("received", 0)
             for name in ("tool_state", "compact_tool_state"))
steps = remote["steps"]
skipped = t["deadband"]["steps_skipped"]
by_cause = t["deadband"]["steps_by_cause"]
with open(f"{out}/remote_steps.csv") as f:
    rows = [(float(r["t_s"]), int(r["tool_state_seq"]), int(r["cause"]))
            for r in csv.DictReader(f)]
errors = []
if states < 5:
    errors.append(f"only {states} tool states reached the node")
if len(rows) != steps:
    errors.append(f"remote_steps.csv has {len(rows)} rows for {steps} steps")
counted = collections.Counter(CAUSES.get(c, f"unknown {c}") for _, _, c in rows)
for name in set(counted) | set(by_cause):
    if counted.get(name, 0) != by_cause.get(name, 0):
        errors.append(f"steps for cause {name}: {counted.get(name, 0)} in remote_steps.csv, "
                      f"{by_cause.get(name, 0)} in remote_summary.json")
if by_cause.get("tool_state", 0) > states:
    errors.append(f"{by_cause['tool_state']} steps for a fresh tool state, {states} received")
t0, t1 = rows[0][0], rows[-1][0]
judged = [r for r in rows if mode == "contact" or r[0] >= t0 + 0.5 * (t1 - t0)]
per_state = collections.Counter(seq for _, seq, _ in judged)
seq, most = per_state.most_common(1)[0] if per_state else (0, 0)
if most > 2:
    errors.append(f"tool state {seq} was stepped {most} times: the node stepped while nothing "
                  "changed")
late = collections.Counter(CAUSES.get(c, f"unknown {c}") for _, _, c in judged
                           if c not in (2, 4))
if mode == "still" and late:
    errors.append(f"with the hand still, steps for {dict(late)}: only a tool state or a held "
                  "model should step")
if skipped < 10:
    errors.append(f"{skipped} loop passes waited: the node did not wait on its socket")
with open(f"{out}/trace.csv") as f:
    contacts = max(int(r["contacts"]) for r in csv.DictReader(f))
if mode == "still" and contacts != 0:
    errors.append(f"the operator held a model with {contacts} contact(s) in free space")
if mode == "contact" and contacts == 0:
    errors.append("the operator never held a contact")
print(f"{mode}: {steps} steps for {states} tool states ({dict(counted)}; judged "
      f"{len(judged)}, at most {most} per tool state), {skipped} passes waited, "
      f"CPU share since the first step {remote.get('cpu_share_since_first_step', -1):.3f} of one core")
if errors:
    for e in errors:
        print("idle loopback: FAILED:", e)
    sys.exit(1)
print("idle loopback: ok")
