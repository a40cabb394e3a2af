#!/usr/bin/env python3
"""Counts the JUnit results under a folder (gtest, rostest and catkin's MISSING
files for tests that produced none), lists the failures, prints one line
'tests: N passed, N failed, N skipped' and exits non-zero if any failed or none ran."""
import pathlib
import sys
import xml.etree.ElementTree as ET

root = pathlib.Path(sys.argv[1])
passed, failed, skipped = 0, [], 0
args = sys.argv[2:]
while len(args) >= 2 and args[0] == "--runner-failed":
    failed.append(args[1])
    args = args[2:]
for path in sorted(root.rglob("*.xml")):
    try:
        tree = ET.parse(path)
    except ET.ParseError as err:
        failed.append(f"{path.name}: unreadable result file ({err})")
        continue
    for case in tree.iter("testcase"):
        name = f"{case.get('classname', '')}.{case.get('name', '')}"
        if case.find("failure") is not None or case.find("error") is not None:
            failed.append(f"{path.name}: {name}")
        elif case.find("skipped") is not None or case.get("status") == "notrun":
            skipped += 1
        else:
            passed += 1
if failed:
    print("failed tests:")
    for f in failed:
        print("  " + f)
if passed + len(failed) == 0:
    print("no test ran")
print(f"tests: {passed} passed, {len(failed)} failed, {skipped} skipped")
sys.exit(1 if failed or passed == 0 else 0)
