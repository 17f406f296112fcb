#!/usr/bin/env python3
"""Checks a loopback run whose hand held still in free space (tests/data/still_hand.csv): the
remote node waited on its socket instead of stepping (issue 33). Every step answers a tool state
that arrived (a few more at most: the session's first passes), the loop passes that waited are
counted, the operator never felt a contact, and every model the operator received was a
keep-alive or an answer, none lost on loopback. No figure per second is asserted: the CPU share
is reported (remote_summary.json cpu_share_since_first_step), not tested."""
import csv
import json
import sys

out = sys.argv[1]
remote = json.load(open(f"{out}/remote_summary.json"))
master = json.load(open(f"{out}/summary.json"))
t = remote["transport"]
states = t["streams"]["tool_state"]["received"]
steps = remote["steps"]
skipped = t["deadband"]["steps_skipped"]
errors = []
if states < 5:
    errors.append(f"only {states} tool states reached the node")
if steps > states + 5:
    errors.append(f"{steps} steps for {states} tool states: the node stepped while nothing changed")
if skipped < 10:
    errors.append(f"{skipped} loop passes waited: the node did not wait on its socket")
with open(f"{out}/trace.csv") as f:
    contacts = max(int(r["contacts"]) for r in csv.DictReader(f))
if contacts != 0:
    errors.append(f"the operator held a model with {contacts} contact(s) in free space")
print(f"still hand: {steps} steps for {states} tool states, {skipped} passes waited, "
      f"CPU share since the first step {remote.get('cpu_share_since_first_step', -1):.3f} of one core")
if errors:
    for e in errors:
        print("idle loopback: FAILED:", e)
    sys.exit(1)
print("idle loopback: ok")
