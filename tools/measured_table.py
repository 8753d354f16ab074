#!/usr/bin/env python3
"""The measured values of the tests that report them, as a markdown table.

Reads the output of voxcone_tests (stdin or files), where tests/support/report.h prints
  [measured] Suite.Test: what = value (bound b)
and writes one row per line: test | what | bound | measured. Example (the real-scenes tests):
  build/voxcone_tests --gtest_filter='Texture*:Environment*:Gltf.*:DirectionalLight.*:Coated*:BsdfCoated.*:BsdfThinDielectric.*:NearLight.*' \\
    | python3 tools/measured_table.py
"""
import fileinput
import re
import sys

LINE = re.compile(r"^\[measured\] (\S+): (.*) = (\S+) \((?:bound (\S+)|no bound)\)$")


def main():
    rows = []
    for line in fileinput.input(sys.argv[1:]):
        m = LINE.match(line.rstrip("\n"))
        if m:
            test, what, value, bound = m.groups()
            rows.append((test, what.replace("|", "\\|"), bound or "(not asserted)", value))
    if not rows:
        sys.exit("measured_table.py: no [measured] lines in the input")
    print("| test | what | bound | measured |")
    print("|---|---|---|---|")
    for r in rows:
        print("| " + " | ".join(r) + " |")


if __name__ == "__main__":
    main()
