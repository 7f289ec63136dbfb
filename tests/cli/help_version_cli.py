#!/usr/bin/env python3
"""--help and --version on every binary and every subcommand.

The subcommands are read from the binaries' own --help: `hysar --help`'s "commands:" list, and
for each command the leaves its help names (`<a|b|c>` in its usage line, "hysar CMD LEAF" usage
lines, a "commands:" list, or two-space-indented entries under a `<step>` usage), so a new
subcommand is walked as soon as its help mentions it. A list of the leaves known today must be
found among them, so that a help text the reading no longer understands fails the test instead
of shrinking the walk.

For each of `hysar`, every command, every leaf and the three clients: `--help` exits 0 and prints
a usage line and an example on stdout; `--version` exits 0 and prints the project's version and a commit line.
For `hysar` also `--version` before the command, and `--log-level`/`--log-format` after it.

Usage: help_version_cli.py BUILD_DIR
"""
import os
import re
import subprocess
import sys

build = sys.argv[1]
hysar = os.path.join(build, "hysar")
clients = [os.path.join(build, "clients", c) for c in ("hysar-hmd", "hysar-projector", "hysar-loadgen")]

# What the walk must find at least (README's command table); more is fine.
KNOWN = {
    "render": [], "serve": [], "admin": ["scene push", "stats", "viewers"],
    "bench": ["encoding", "accuracy", "stability", "serve"],
    "eval": ["optics", "resolution", "compare", "report"],
    "calibrate": ["patterns", "decode", "invert", "colour", "optics", "capture", "simulate"],
}

failures = []
checked = 0


def run(args, env=None):
    e = dict(os.environ)
    e.pop("HYSAR_LOG_LEVEL", None)
    e.pop("HYSAR_LOG_FORMAT", None)
    e.pop("HYSAR_DEVICE", None)
    e.update(env or {})
    p = subprocess.run(args, stdin=subprocess.DEVNULL, capture_output=True, text=True,
                       errors="replace", timeout=120, env=e)
    return p.returncode, p.stdout, p.stderr


def fail(what, why, out="", err=""):
    failures.append(what)
    print(f"FAIL {what}: {why}")
    for name, text in (("stdout", out), ("stderr", err)):
        for line in text.splitlines()[:8]:
            print(f"    {name}: {line}")


def project_version():
    text = open(os.path.join(build, "CMakeCache.txt")).read()
    m = re.search(r"^CMAKE_PROJECT_VERSION:STATIC=(\S+)$", text, re.M)
    return m.group(1) if m else None


VERSION = project_version()
if not VERSION:
    sys.exit("help_version_cli: no CMAKE_PROJECT_VERSION in the build's CMakeCache.txt")


def check_help(cmd, label):
    global checked
    checked += 1
    rc, out, err = run(cmd + ["--help"])
    if rc != 0:
        fail(f"{label} --help", f"exit status {rc}, expected 0", out, err)
    elif not re.search(r"^usage: \S", out, re.M | re.I):
        fail(f"{label} --help", "no usage line on stdout", out, err)
    elif not re.search(r"^examples?:\s+\S*(hysar|hysar-\w+) ", out, re.M | re.I):
        fail(f"{label} --help", "no example (a line 'example: hysar ...')", out, err)
    return out


def check_version(cmd, label, program, device):
    global checked
    checked += 1
    rc, out, err = run(cmd)
    if rc != 0:
        fail(label, f"exit status {rc}, expected 0", out, err)
        return
    lines = out.splitlines()
    if not lines or lines[0] != f"{program} {VERSION}":
        fail(label, f"the first line is not '{program} {VERSION}'", out, err)
    elif not any(re.fullmatch(r"commit: ([0-9a-f]{7,40}(-dirty)?|unknown)", l) for l in lines):
        fail(label, "no 'commit: HASH' (or 'commit: unknown') line", out, err)
    elif not any(l.startswith("build type: ") for l in lines):
        fail(label, "no 'build type:' line", out, err)
    elif device and not any(l.startswith("vulkan device: ") for l in lines):
        fail(label, "no 'vulkan device:' line", out, err)


def commands_section(text):
    """The first words of the entries of a "commands:" list (two-word entries like "scene push"
    when the second word is not an option or a placeholder)."""
    found, inside = [], False
    for line in text.splitlines():
        if line.strip() == "commands:":
            inside = True
            continue
        if inside:
            if not line.strip():
                break
            m = re.match(r"^  ([a-z][a-z0-9-]*)( [a-z][a-z0-9-]*)?(?= |$)", line)
            if m:
                found.append((m.group(1) + (m.group(2) or "")).strip())
    return found


def leaves_of(cmd, help_text):
    leaves = []
    usage = [l for l in help_text.splitlines() if re.match(rf"^(usage:)?\s*hysar {cmd}\b", l)]
    for l in usage:
        m = re.search(rf"hysar {cmd} <([a-z]+(\|[a-z]+)+)>", l)  # <a|b|c>; <step> is a placeholder
        if m:
            leaves += m.group(1).split("|")
        m = re.search(rf"hysar {cmd} ([a-z][a-z0-9-]*)\b", l)
        if m:
            leaves.append(m.group(1))
    leaves += commands_section(help_text)
    if any(re.search(rf"hysar {cmd} <[a-z]+>", l) for l in usage):
        leaves += re.findall(r"^  ([a-z][a-z0-9-]*)(?= )", help_text, re.M)
    unique = []
    for leaf in leaves:
        if leaf not in unique:
            unique.append(leaf)
    return unique


top = check_help([hysar], "hysar")
commands = commands_section(top)
# `hysar --help` names every subcommand on a line of its own ("    bench serve   ...") under its
# command, so that a newcomer sees the whole tool in one page.
LISTED = {cmd: list(leaves) for cmd, leaves in KNOWN.items()}
LISTED["admin"].append("kick")
LISTED["cluster"] = ["config"]
for cmd, leaves in LISTED.items():
    for leaf in leaves:
        checked += 1
        if not re.search(rf"^    {cmd} {leaf}\b", top, re.M):
            fail("hysar --help", f"'{cmd} {leaf}' is not listed under its command")
for cmd, known_leaves in KNOWN.items():
    if cmd not in commands:
        fail("hysar --help", f"'{cmd}' is not in its commands list ({commands})")
check_version([hysar, "--version"], "hysar --version", "hysar", True)

for cmd in commands:
    text = check_help([hysar, cmd], f"hysar {cmd}")
    check_version([hysar, cmd, "--version"], f"hysar {cmd} --version", "hysar", True)
    leaves = leaves_of(cmd, text)
    print(f"hysar {cmd}: {', '.join(leaves) if leaves else 'no subcommands'}")
    missing = [l for l in KNOWN.get(cmd, []) if l not in leaves]
    if missing:
        fail(f"hysar {cmd} --help", f"the walk did not find {missing} in it (found {leaves})")
    for leaf in leaves:
        argv = [hysar, cmd] + leaf.split()
        check_help(argv, "hysar " + " ".join(argv[1:]))
        check_version(argv + ["--version"], "hysar " + " ".join(argv[1:]) + " --version", "hysar",
                      True)

# The global options anywhere on the line.
check_version([hysar, "--version", "eval", "optics"], "hysar --version eval optics", "hysar", True)
check_version([hysar, "--log-level", "debug", "render", "--log-format=json", "--version"],
              "hysar --log-level debug render --log-format=json --version", "hysar", True)

for client in clients:
    name = os.path.basename(client)
    check_help([client], name)
    check_version([client, "--version"], f"{name} --version", name, False)
    # Before other options too, and without a token or a server.
    check_version([client, "--connect", "127.0.0.1:1", "--version"], f"{name} ... --version", name,
                  False)

print(f"{checked - len(failures)} passed, {len(failures)} failed")
sys.exit(1 if failures else 0)
