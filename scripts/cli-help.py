#!/usr/bin/env python3
"""Rewrites the "Every flag" section of docs/cli.md from the binary's own `jem COMMAND --help`, each help line that runs
past 118 characters wrapped at a word with its continuation under the description's column.

Usage: scripts/cli-help.py [JEM]   (JEM: the binary; default target/release/jem)
"""
import re
import subprocess
import sys
import textwrap
from pathlib import Path

WIDTH = 118
COMMANDS = ["match", "rectify", "sequence", "batch", "eval", "report", "viz", "config", "synth", "degrade"]


def wrap(line):
    if len(line) <= WIDTH:
        return [line]
    # The description starts after the flag column (two or more spaces), else after the line's own indent.
    m = re.match(r"^(\s*\S.*?\s{2,})(\S.*)$", line) or re.match(r"^(\s*)(.*)$", line)
    indent = " " * len(m.group(1))
    return textwrap.wrap(line, WIDTH, subsequent_indent=indent, break_long_words=False, break_on_hyphens=False)


def main():
    root = Path(__file__).resolve().parent.parent
    jem = sys.argv[1] if len(sys.argv) > 1 else str(root / "target/release/jem")
    page = root / "docs/cli.md"
    text = page.read_text()
    head = text[: text.index("### jem match")]
    blocks = []
    for cmd in COMMANDS:
        out = subprocess.run([jem, cmd, "--help"], capture_output=True, text=True, check=True).stdout
        lines = [w for line in out.rstrip("\n").split("\n") for w in wrap(line.rstrip())]
        blocks.append(f"### jem {cmd}\n\n```text\n" + "\n".join(lines) + "\n```\n")
    page.write_text(head + "\n".join(blocks))


if __name__ == "__main__":
    main()
