#!/usr/bin/python3
"""A loopback run asked for the f64 tool states and the float contact models
(master_station --float-tool-states --float-models): the session agreed on them, every tool state
and model went in that encoding (none in the compact ones), both sides counted the same stream,
and nothing went non-finite.
Usage: float_encodings_check.py RUN_DIR"""
import json
import sys


def main(run):
    s = json.load(open(f"{run}/summary.json"))
    t = s["transport"]
    streams = t["streams"]
    remote_streams = s["remote"]["transport"]["streams"]
    errors = []

    def count(table, name, key):
        return int(table.get(name, {}).get(key, 0))

    if t["deadband"].get("compact_tool_states") is not False:
        errors.append(f"compact_tool_states is {t['deadband'].get('compact_tool_states')!r}")
    if t["deadband"].get("compact_models") is not False:
        errors.append(f"compact_models is {t['deadband'].get('compact_models')!r}")
    if count(streams, "tool_state", "sent") < 100:
        errors.append(f"only {count(streams, 'tool_state', 'sent')} f64 tool states sent")
    if count(remote_streams, "tool_state", "received") < 100:
        errors.append("the remote node received fewer than 100 f64 tool states")
    for name in ("compact_tool_state",):
        if count(streams, name, "sent") or count(remote_streams, name, "received"):
            errors.append(f"{name} datagrams went though the float encodings were asked for")
    if count(streams, "contact_model", "received") < 10:
        errors.append("fewer than 10 float contact models arrived")
    if count(streams, "compact_contact_model", "received"):
        errors.append("compact contact models arrived though the float encoding was asked for")
    if s.get("nonfinite_count", 0) != 0:
        errors.append(f"nonfinite_count {s.get('nonfinite_count')}")
    for e in errors:
        print("float_encodings_check:", e)
    if not errors:
        print(f"float_encodings_check: ok ({count(streams, 'tool_state', 'sent')} f64 tool states, "
              f"{count(streams, 'contact_model', 'received')} float contact models)")
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
