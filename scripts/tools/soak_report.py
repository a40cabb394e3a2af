#!/usr/bin/env python3
"""The verdict of a soak (scripts/checks/soak) from its samples and the player's summary.

usage: soak_report.py SAMPLES.csv PLAYER.yaml --warmup M --max-growth P --summary OUT.md [--title T]
                      [--map-process NAME]

SAMPLES.csv is scripts/tools/soak_sampler.py's (a row a minute: per process its
pid and the median and maximum of its resident memory, per stage its counts);
PLAYER.yaml the paced player's summary (played, fused, skipped, lost, timed_out,
stopped_on_bad_input, wall_s). The soak fails when
  - a process grew by more than P % of its resident memory (the minute's
    median) from the row of minute M to the last row, or exited ("gone") or
    changed its pid (respawned) after it started ("" before: not started).
    For the process that holds the TSDF map (--map-process, default
    fusion_manager) the memory judged is what it holds beyond the map's own
    voxels and mesh (the tsdf_voxel_mb and tsdf_mesh_mb columns): a drive
    played in a loop keeps confirming voxels that had too few observations,
    so the map grows for many passes, and that is the map, not a leak. Its
    plain resident memory and the map's are reported beside it;
  - the player did not fuse every frame set it played, skipped or timed one
    out, stopped on bad input, or wrote no summary;
  - there are too few rows to measure a growth after minute M.
Writes OUT.md (the tables and "Result: PASS" or "Result: FAIL: ...") and
prints the failures joined by "; " (nothing when it passes).
"""
import argparse
import csv
import math
import sys

STAGES = ["sync", "depth", "detector", "depth_mask", "tsdf"]


def read_counts(path):
    with open(path) as f:
        return dict(line.split(": ", 1) for line in f.read().splitlines() if ": " in line)


def map_mb(r):
    """The TSDF map's own memory in a sampler row (voxels + mesh, MB), or None."""
    try:
        return float(r.get("tsdf_voxel_mb", "")) + float(r.get("tsdf_mesh_mb", ""))
    except ValueError:
        return None


def verdict(rows, counts, warmup, max_growth, map_process="fusion_manager"):
    """(failures, memory table rows) for the samples `rows` (dicts) and the
    player's `counts` (None: no summary). A table row: (process, what is
    judged, at minute `warmup`, at the end, growth %, highest reading)."""
    failures, table = [], []
    if counts is None:
        failures.append("the player wrote no summary (see launch.log)")
        counts = {}
    procs = [k[: -len("_rss_mb")] for k in (rows[0].keys() if rows else [])
             if k.endswith("_rss_mb") and k != "player_rss_mb"]
    base = next((r for r in rows if float(r["minute"]) >= warmup - 0.05), None)
    if len(rows) < 2 or base is None or base is rows[-1]:
        failures.append(f"too few samples ({len(rows)}) for a growth after minute {warmup}")
    else:
        for p in procs:
            vals = [r[p + "_rss_mb"] for r in rows if r[p + "_rss_mb"] != ""]  # "": not started yet
            pids = {r[p + "_pid"] for r in rows if r[p + "_pid"] != ""}
            if "gone" in vals or len(pids) > 1 or base[p + "_rss_mb"] in ("", "gone") \
                    or rows[-1][p + "_rss_mb"] in ("", "gone"):
                failures.append(f"{p} exited or was respawned during the soak (pids {sorted(pids)})")
                continue
            b, e = float(base[p + "_rss_mb"]), float(rows[-1][p + "_rss_mb"])
            peak = max(float(r[p + "_rss_max_mb"]) for r in rows if r[p + "_rss_max_mb"] not in ("", "gone"))
            judged = "RSS"
            if p == map_process and map_mb(base) is not None and map_mb(rows[-1]) is not None:
                table.append((p, "RSS", b, e, 100.0 * (e - b) / b, peak))
                table.append(("TSDF map", "voxels + mesh", map_mb(base), map_mb(rows[-1]),
                              100.0 * (map_mb(rows[-1]) - map_mb(base)) / map_mb(base), None))
                b, e, peak, judged = b - map_mb(base), e - map_mb(rows[-1]), None, "RSS beyond the map"
            growth = 100.0 * (e - b) / b
            table.append((p, judged, b, e, growth, peak))
            if growth > max_growth:
                failures.append(f"{p} grew by {growth:.1f} % ({judged}: {b:.1f} -> {e:.1f} MB) after minute {warmup}")
    played, fused = int(counts.get("played", -1)), int(counts.get("fused", -2))
    for key in ["skipped", "lost", "timed_out"]:
        if counts and counts.get(key, "0") != "0":
            failures.append(f"player: {key} {counts[key]}")
    if counts and played != fused:
        failures.append(f"player: {played} frame sets played but {fused} fused")
    if counts.get("stopped_on_bad_input", "false") != "false":
        failures.append("the player stopped on bad input")
    return failures, table


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("samples")
    ap.add_argument("player")
    ap.add_argument("--warmup", type=int, required=True)
    ap.add_argument("--max-growth", type=float, required=True)
    ap.add_argument("--summary", required=True)
    ap.add_argument("--title", default="")
    ap.add_argument("--map-process", default="fusion_manager")
    args = ap.parse_args()
    with open(args.samples) as f:
        rows = list(csv.DictReader(f))
    try:
        counts = read_counts(args.player)
    except OSError:
        counts = None
    failures, table = verdict(rows, counts, args.warmup, args.max_growth, args.map_process)
    counts = counts or {}
    lines = [f"# Soak: {args.title}", "",
             f"{len(rows)} samples, one a minute (samples.csv); resident memory as the median of the minute's "
             f"readings (every 5 s); its growth from the end of minute {args.warmup} to the end, allowed "
             f"{args.max_growth:g} %.", "",
             f"| process | memory | at minute {args.warmup} (MB) | at the end (MB) | growth | highest reading (MB) |",
             "|---|---|---|---|---|---|"]
    lines += [f"| {p} | {what} | {b:.1f} | {e:.1f} | {g:+.1f} % | {'' if peak is None else f'{peak:.1f}'} |"
              for p, what, b, e, g, peak in table]
    last = rows[-1] if rows else {}
    lines += ["", "| stage | inputs | outputs | dropped | backlog at the end |", "|---|---|---|---|---|"]
    for s in STAGES:
        if last.get(s + "_inputs", "") != "":
            lines.append(f"| {s} | {last[s + '_inputs']} | {last[s + '_outputs']} | {last[s + '_dropped']} | "
                         f"{last[s + '_backlog'] or 'n/a'} |")
    first = rows[0] if rows else {}
    lines += ["", f"TSDF blocks in memory: first sample {first.get('tsdf_blocks', '?')}, last "
                  f"{last.get('tsdf_blocks', '?')}; mesh triangles: first {first.get('tsdf_mesh_triangles', '?')}, "
                  f"last {last.get('tsdf_mesh_triangles', '?')}."]
    wall = float(counts.get("wall_s", "nan"))
    lines += ["", f"Player: {counts.get('played', '?')} frame sets played, {counts.get('fused', '?')} fused, "
                  f"{counts.get('skipped', '?')} skipped, {counts.get('lost', '0')} lost, {counts.get('timed_out', '?')} timed out, in "
                  f"{'?' if math.isnan(wall) else f'{wall:.0f}'} s.", "",
              "Result: " + ("PASS" if not failures else "FAIL: " + "; ".join(failures))]
    with open(args.summary, "w") as f:
        f.write("\n".join(lines) + "\n")
    print("; ".join(failures))
    return 0


if __name__ == "__main__":
    sys.exit(main())
