#!/usr/bin/env python3
"""Every Catch2 test name is a CTest name: CTest splits a name at ';' (a CMake list), so a test
whose name holds one is registered as two that match nothing and never run (found twice:
issue 30's 15 never-run tests, and again in issue 33). This fails on any such name.

Usage: check_test_names.py <source root>
"""
import glob
import os
import re
import sys

root = sys.argv[1]
bad = []
for path in glob.glob(os.path.join(root, "tests", "**", "*.cpp"), recursive=True):
    text = open(path, encoding="utf-8").read()
    for m in re.finditer(r'TEST_CASE\(((?:"(?:[^"\\]|\\.)*"\s*)+)', text):
        name = "".join(re.findall(r'"((?:[^"\\]|\\.)*)"', m.group(1)))
        if ";" in name:
            bad.append(f"{os.path.relpath(path, root)}:{text[:m.start()].count(chr(10)) + 1}: {name}")
for b in bad:
    print(f"test name with ';' (CTest would split it and never run it): {b}")
print(f"{len(bad)} bad test name(s)")
sys.exit(1 if bad else 0)
