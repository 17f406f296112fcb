#!/usr/bin/python3
"""Each program's help: a short main group, and no history.

For each --program NAME=PATH, runs `PATH --help` and, where that help offers --help-all, also
`PATH --help-all` (every option, the advanced groups and the subcommands included), and checks:

- the main group (the options under the first "Options:" heading of --help, -h,--help, --help-all
  and --config included) has at most N options, for each --main-max NAME=N;
- an option group that --help only counts ("Advanced (26 options, listed by --help-all):") has
  that many options under --help-all, none of them in the main group;
- no help text tells history: "issue " and a digit, a record folder's name ("_stop", "twenty-fifth
  stop"), or a link into the per-run record folders that left the tree (docs/frontier,
  docs/passivity, docs/deadband/, docs/issue...).

Exit status 0 when every check holds, 1 otherwise.

Usage: help_text_test.py --program NAME=PATH [...] [--main-max NAME=N ...]
"""

import argparse
import re
import subprocess
import sys

HISTORY = [
    (re.compile(r"issue\s+\d", re.I), "an issue number"),
    (re.compile(r"_stop\b"), "a record folder's name"),
    (re.compile(r"\b\w+(?:st|nd|rd|th)\s+stop\b", re.I), "a record folder's name"),
    (re.compile(r"docs/(?:frontier|passivity|deadband/|issue)"), "a per-run record folder"),
]
COUNTED_GROUP = re.compile(r"^(\w[\w ]*) \((\d+) options, listed by --help-all\):$", re.M)


def run(argv):
    try:
        out = subprocess.run(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                             timeout=60)
    except (OSError, subprocess.TimeoutExpired) as error:
        return None, str(error)
    return out.returncode, out.stdout


def section(text, heading):
    """The lines under `heading` (a line of its own) up to the next blank line."""
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if line == heading:
            body = []
            for rest in lines[i + 1:]:
                if not rest.strip():
                    break
                body.append(rest)
            return body
    return None


def option_names(lines, indent):
    pattern = re.compile("^" + indent + r"(-\S+)")
    names = []
    for line in lines:
        match = pattern.match(line)
        if match:
            names.append(match.group(1))
    return names


def group_options(help_all, group):
    """The options of option group `group` in a --help-all text ("GROUP:" then "  Options:")."""
    lines = help_all.splitlines()
    for i, line in enumerate(lines):
        if line != group + ":":
            continue
        names = []
        in_options = False
        for rest in lines[i + 1:]:
            if not rest.strip():
                break
            if rest == "  Options:":
                in_options = True
                continue
            if in_options:
                match = re.match(r"^    (-\S+)", rest)
                if match:
                    names.append(match.group(1))
        return names
    return None


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--program", action="append", default=[], metavar="NAME=PATH")
    parser.add_argument("--main-max", action="append", default=[], metavar="NAME=N")
    args = parser.parse_args()
    programs = dict(item.split("=", 1) for item in args.program)
    main_max = {name: int(n) for name, n in (item.split("=", 1) for item in args.main_max)}
    unknown = set(main_max) - set(programs)
    if unknown:
        parser.error(f"--main-max for a program not given: {', '.join(sorted(unknown))}")

    failures = []
    for name, path in programs.items():
        rc, text = run([path, "--help"])
        if rc != 0 or not text.strip():
            failures.append(f"{name} --help: exit {rc}: {text.strip()[:200]}")
            continue
        texts = {"--help": text}
        if re.search(r"^\s+--help-all\b", text, flags=re.M):
            rc, all_text = run([path, "--help-all"])
            if rc != 0 or not all_text.strip():
                failures.append(f"{name} --help-all: exit {rc}: {all_text.strip()[:200]}")
            else:
                texts["--help-all"] = all_text

        main_group = section(text, "Options:")
        main_names = option_names(main_group or [], "  ")
        if name in main_max:
            if main_group is None:
                failures.append(f"{name} --help: no \"Options:\" heading")
            elif len(main_names) > main_max[name]:
                failures.append(f"{name} --help: {len(main_names)} options in the main group, "
                                f"more than {main_max[name]}: {' '.join(main_names)}")
            print(f"{name}: {len(main_names)} options in the main group (at most "
                  f"{main_max[name]})")

        for match in COUNTED_GROUP.finditer(text):
            group, count = match.group(1), int(match.group(2))
            names = group_options(texts.get("--help-all", ""), group)
            if names is None:
                failures.append(f"{name} --help-all does not list group {group}")
                continue
            if len(names) != count:
                failures.append(f"{name}: --help counts {count} {group} options, --help-all lists "
                                f"{len(names)}")
            both = sorted(set(names) & set(main_names))
            if both:
                failures.append(f"{name}: in the main group and in {group}: {' '.join(both)}")
            print(f"{name}: {group}, {len(names)} options under --help-all")

        for flag, help_text in texts.items():
            for line_number, line in enumerate(help_text.splitlines(), start=1):
                for pattern, what in HISTORY:
                    found = pattern.search(line)
                    if found:
                        failures.append(f"{name} {flag}, line {line_number}: {what} "
                                        f"({found.group(0)!r}): {line.strip()}")
        print(f"{name}: {', '.join(texts)} checked for history")

    if failures:
        print(f"\n{len(failures)} problem(s):")
        for failure in failures:
            print("  " + failure)
        return 1
    print(f"\n{len(programs)} program(s): every help short enough and without history")
    return 0


if __name__ == "__main__":
    sys.exit(main())
