#!/usr/bin/env python3
"""Checks that the remote node waited on its socket instead of stepping when a step would see
nothing new (issue 33). Usage: idle_loopback_check.py RUN_DIR [still|contact]
- still (default): a run whose hand held still in free space (tests/data/still_hand.csv): every
  step answers a tool state that arrived (a few more at most: the session's first passes), the
  loop passes that waited are counted, and the operator never felt a contact.
- contact: a fig75 run without deadband (--deadband 0): tool states come every tick at an
  unchanged pose in between, so each is stepped once, and once more at most when its model was
  held by the model period (stepped again at the period's end, not in a loop); the operator felt
  contact.
No figure per second is asserted: the CPU share is reported (remote_summary.json
cpu_share_since_first_step), not tested."""
import csv
import json
import sys

out = sys.argv[1]
mode = sys.argv[2] if len(sys.argv) > 2 else "still"
remote = json.load(open(f"{out}/remote_summary.json"))
master = json.load(open(f"{out}/summary.json"))
t = remote["transport"]
states = t["streams"]["tool_state"]["received"]
steps = remote["steps"]
skipped = t["deadband"]["steps_skipped"]
errors = []
if states < 5:
    errors.append(f"only {states} tool states reached the node")
most = states + 5 if mode == "still" else 2 * states + 10
if steps > most:
    errors.append(f"{steps} steps for {states} tool states (at most {most}): the node stepped "
                  "while nothing changed")
if skipped < 10:
    errors.append(f"{skipped} loop passes waited: the node did not wait on its socket")
with open(f"{out}/trace.csv") as f:
    contacts = max(int(r["contacts"]) for r in csv.DictReader(f))
if mode == "still" and contacts != 0:
    errors.append(f"the operator held a model with {contacts} contact(s) in free space")
if mode == "contact" and contacts == 0:
    errors.append("the operator never held a contact")
print(f"{mode}: {steps} steps for {states} tool states, {skipped} passes waited, "
      f"CPU share since the first step {remote.get('cpu_share_since_first_step', -1):.3f} of one core")
if errors:
    for e in errors:
        print("idle loopback: FAILED:", e)
    sys.exit(1)
print("idle loopback: ok")
