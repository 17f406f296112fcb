#!/usr/bin/python3
"""Every option a README command uses exists.

Reads the README's ```sh blocks, splits them into commands (at &&, ||, ;, |, &), and for each
command whose program is one of --program NAME=PATH (matched by the basename of the command's
first word: ./deploy/run-loopback and build/slave_sim/slave_sim alike) runs `PATH --help`
(`PATH SUBCOMMAND --help` for a subcommand its help lists, e.g. `slave_sim inspect`), or
`--help-all` where --help offers it (the advanced options too), and checks that every --option
the command uses appears in that help text. The options inside
run-loopback's and deadband-table's --master-args "..." and --slave-args "..." are checked
against master_station's and slave_sim's help. Commands of other programs (cmake, sudo, ...) are
listed as not checked. Exit status 0 when every checked option exists, 1 otherwise (or when no
command could be checked at all, which would mean the README's blocks were not found).

Usage: readme_commands_test.py --readme README.md --program NAME=PATH [--program NAME=PATH ...]
"""

import argparse
import os
import re
import shlex
import subprocess
import sys

SEPARATORS = {"&&", "||", ";", "|", "&", "(", ")", "((", "))", ";;"}
REDIRECTIONS = {">", ">>", "<", ">&", "<&", ">|", "&>"}
# Options whose value is another program's command line.
NESTED = {"--master-args": "master_station", "--slave-args": "slave_sim"}


def sh_blocks(text):
    """The bodies of the ```sh fenced blocks, in order."""
    return re.findall(r"^[ \t]*```sh[ \t]*\n(.*?)^[ \t]*```", text, flags=re.S | re.M)


def tokens_of(line):
    lexer = shlex.shlex(line, posix=True, punctuation_chars=True)
    lexer.whitespace_split = True
    lexer.commenters = "#"
    return list(lexer)


def commands_of(block):
    """Each command of a block as its list of words (continuation lines joined)."""
    commands = []
    for line in block.replace("\\\n", " ").splitlines():
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        try:
            words = tokens_of(line)
        except ValueError as error:  # an unbalanced quote: say so rather than guess
            raise SystemExit(f"readme_commands_test: cannot split README line {line!r}: {error}")
        current = []
        skip_next = False
        for word in words:
            if skip_next:
                skip_next = False
                continue
            if word in SEPARATORS:
                if current:
                    commands.append(current)
                current = []
            elif word in REDIRECTIONS or re.fullmatch(r"\d?[<>]{1,2}&?", word):
                skip_next = not word.endswith("&")
            else:
                current.append(word)
        if current:
            commands.append(current)
    return commands


def program_words(words):
    """The command without leading VAR=value assignments and sudo."""
    i = 0
    while i < len(words) and (re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*=.*", words[i]) or
                              words[i] == "sudo"):
        i += 1
    return words[i:]


class Helps:
    def __init__(self, programs):
        self.programs = programs
        self.cache = {}

    def run(self, argv):
        try:
            return subprocess.run(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                  text=True, timeout=120).stdout
        except (OSError, subprocess.TimeoutExpired) as error:
            print(f"  cannot run {' '.join(argv)}: {error}")
            return ""

    def text(self, name, subcommand=None):
        key = (name, subcommand)
        if key not in self.cache:
            argv = [self.programs[name]] + ([subcommand] if subcommand else [])
            text = self.run(argv + ["--help"])
            if re.search(r"^\s+--help-all\b", text, flags=re.M):
                text = self.run(argv + ["--help-all"])
            self.cache[key] = text
        return self.cache[key]

    def subcommands(self, name):
        """The words under a CLI11 help's "Subcommands:" heading."""
        text = self.text(name)
        match = re.search(r"^Subcommands:\n((?:[ \t].*\n?)*)", text, flags=re.M)
        if not match:
            return set()
        return set(re.findall(r"^  (\S+)", match.group(1), flags=re.M))


def has_option(help_text, option):
    return re.search(r"(?<![\w-])" + re.escape(option) + r"(?![\w-])", help_text) is not None


def check_options(helps, name, subcommand, words, where, failures):
    """Checks each --option of `words` against NAME's help; recurses into nested command lines."""
    help_text = helps.text(name, subcommand)
    label = name + (" " + subcommand if subcommand else "")
    if not help_text.strip():
        failures.append(f"{where}: `{label} --help` printed nothing")
        return 0
    checked = 0
    i = 0
    while i < len(words):
        word = words[i]
        if word.startswith("--") and len(word) > 2:
            option, _, value = word.partition("=")
            checked += 1
            if not has_option(help_text, option):
                failures.append(f"{where}: {label} has no option {option} (not in its help)")
            if option in NESTED:
                nested = value if value else (words[i + 1] if i + 1 < len(words) else "")
                if not value:
                    i += 1
                inner = NESTED[option]
                if inner in helps.programs:
                    checked += check_options(helps, inner, None, shlex.split(nested),
                                             f"{where} ({option})", failures)
        i += 1
    return checked


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--readme", required=True)
    parser.add_argument("--program", action="append", default=[], metavar="NAME=PATH",
                        help="a program whose README commands are checked, and its executable")
    args = parser.parse_args()

    programs = {}
    for item in args.program:
        name, sep, path = item.partition("=")
        if not sep or not name or not path:
            parser.error(f"--program {item!r}: expected NAME=PATH")
        programs[name] = path
    failures = []
    missing = set()  # programs the README uses whose executable is not there

    with open(args.readme, encoding="utf-8") as f:
        text = f.read()
    helps = Helps(programs)
    commands_checked = 0
    options_checked = 0
    not_checked = set()
    for block_index, block in enumerate(sh_blocks(text), start=1):
        for words in commands_of(block):
            words = program_words(words)
            if not words:
                continue
            name = os.path.basename(words[0])
            if name not in programs:
                not_checked.add(name)
                continue
            if not os.access(programs[name], os.X_OK):
                if name not in missing:
                    missing.add(name)
                    failures.append(f"program {name}: {programs[name]} is not an executable file "
                                    f"(the README runs it; build it first)")
                continue
            subcommand = None
            if len(words) > 1 and not words[1].startswith("-") and words[1] in helps.subcommands(
                    name):
                subcommand = words[1]
            where = f"README sh block {block_index}: `{shlex.join(words)}`"
            n = check_options(helps, name, subcommand, words[1:], where, failures)
            commands_checked += 1
            options_checked += n
            print(f"checked {n:2d} option(s): {shlex.join(words)}")

    if not_checked:
        print("not checked (not a program of this project): " + ", ".join(sorted(not_checked)))
    if commands_checked == 0:
        failures.append(f"no README command of {', '.join(sorted(programs))} found in "
                        f"{args.readme}'s ```sh blocks")
    if failures:
        print(f"\n{len(failures)} problem(s):")
        for failure in failures:
            print("  " + failure)
        return 1
    print(f"\n{commands_checked} command(s), {options_checked} option(s): every option exists")
    return 0


if __name__ == "__main__":
    sys.exit(main())
