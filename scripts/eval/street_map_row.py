"""One row of scripts/eval/street_map's table, from offline_mapper's and
map_accuracy's outputs in MAP_DIR (and the reference map's cloud)."""
import csv
import os
import statistics
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tools"))
from topdown_png import read_pcd  # noqa: E402


def pcd_z(path):
    """z of every point of a PCD file (scripts/tools/topdown_png.py's reader)."""
    return read_pcd(path)[:, 2]


def main():
    preset, variant, det, m, ref = sys.argv[1:6]
    rows = {float(r["t"]): r for r in csv.DictReader(open(os.path.join(m, "cloud_accuracy.csv")))}
    rows_all = {float(r["t"]): r for r in csv.DictReader(open(os.path.join(m, "cloud_all_accuracy.csv")))}
    a, c = rows[0.1], rows[0.25]
    high = int((pcd_z(os.path.join(m, "cloud.pcd")) >= 0.3).sum())
    high_ref = int((pcd_z(os.path.join(ref, "cloud.pcd")) >= 0.3).sum())
    depth_ms = statistics.median(float(r["sweep_ms"]) for r in csv.DictReader(open(os.path.join(m, "timings.csv"))))
    vehicles, right = "-", "-"
    vpath = os.path.join(m, "vehicles.csv")
    if os.path.exists(vpath):
        v = list(csv.DictReader(open(vpath)))
        n = {k: sum(1 for r in v if r["motion"] == k) for k in ("moving", "parked", "undecided")}
        vehicles = f"{n['moving']} / {n['parked']} / {n['undecided']}"
        known = [r for r in v if r["true_moving"] in ("0", "1")]
        mov = [r for r in known if r["motion"] == "moving"]
        par = [r for r in known if r["motion"] == "parked"]
        ok_m = sum(1 for r in mov if r["true_moving"] == "1")
        ok_p = sum(1 for r in par if r["true_moving"] == "0")
        right = f"{ok_m}/{len(mov)} / {ok_p}/{len(par)}"
    print(f"| {preset} | {variant} | {det} | {int(a['points'])} | {100 * float(a['accuracy']):.1f} % | "
          f"{100 * float(c['completeness']):.1f} % | {c['trails']} / {rows_all[0.25]['trails']} | {high} / {high_ref} | "
          f"{depth_ms:.0f} | {vehicles} | {right} |")


if __name__ == "__main__":
    main()
