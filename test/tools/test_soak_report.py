"""scripts/tools/soak_report.py: the soak's verdict on hand-made samples."""
import os
import sys
import unittest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "scripts", "tools"))
import soak_report  # noqa: E402

GOOD_PLAYER = {"played": "120", "fused": "120", "skipped": "0", "timed_out": "0", "stopped_on_bad_input": "false"}


def row(minute, pid, median, peak):
    """A sampler row with one process (m) and the player (p, ignored by the memory rule)."""
    return {"minute": f"{minute:.2f}", "m_pid": pid, "m_rss_mb": median, "m_rss_max_mb": peak,
            "player_pid": "9", "player_rss_mb": "90.0", "player_rss_max_mb": "90.0"}


class SoakVerdict(unittest.TestCase):
    def test_flat_memory_and_every_frame_set_fused_pass(self):
        rows = [row(1, "", "", ""), row(2, "5", "400.0", "480.0"), row(3, "5", "430.0", "500.0"),
                row(4, "5", "439.0", "470.0")]
        failures, table = soak_report.verdict(rows, GOOD_PLAYER, warmup=2, max_growth=10)
        self.assertEqual(failures, [])
        # 400 -> 439 MB: +9.75 %; the highest reading of the run, 500 MB.
        self.assertEqual(len(table), 1)
        name, what, base, end, growth, peak = table[0]
        self.assertEqual((name, what, base, end, peak), ("m", "RSS", 400.0, 439.0, 500.0))
        self.assertAlmostEqual(growth, 9.75)

    def test_growth_beyond_the_limit_fails_naming_the_process(self):
        rows = [row(2, "5", "400.0", "400.0"), row(3, "5", "441.0", "441.0")]
        failures, _ = soak_report.verdict(rows, GOOD_PLAYER, warmup=2, max_growth=10)
        self.assertEqual(failures, ["m grew by 10.2 % (RSS: 400.0 -> 441.0 MB) after minute 2"])

    def test_the_maps_process_is_judged_beyond_the_map(self):
        # The map grows from 250 to 330 MB (voxels 200 -> 220, mesh 50 -> 110):
        # the process's RSS 600 -> 690 MB (+15 %), what lies beyond the map
        # 350 -> 360 MB (+2.9 %): a growing map, not a leak.
        rows = [dict(row(2, "5", "600.0", "650.0"), tsdf_voxel_mb="200", tsdf_mesh_mb="50"),
                dict(row(3, "5", "690.0", "720.0"), tsdf_voxel_mb="220", tsdf_mesh_mb="110")]
        failures, table = soak_report.verdict(rows, GOOD_PLAYER, warmup=2, max_growth=10, map_process="m")
        self.assertEqual(failures, [])
        self.assertEqual([t[:2] for t in table], [("m", "RSS"), ("TSDF map", "voxels + mesh"), ("m", "RSS beyond the map")])
        self.assertAlmostEqual(table[0][4], 15.0)
        self.assertAlmostEqual(table[1][4], 32.0)
        self.assertEqual(table[2][2:4], (350.0, 360.0))
        self.assertAlmostEqual(table[2][4], 100.0 * 10 / 350)
        # 60 MB more RSS: 420 MB beyond the map (+20 %) fails, naming what was judged.
        rows[1]["m_rss_mb"] = "750.0"
        failures, _ = soak_report.verdict(rows, GOOD_PLAYER, warmup=2, max_growth=10, map_process="m")
        self.assertEqual(failures, ["m grew by 20.0 % (RSS beyond the map: 350.0 -> 420.0 MB) after minute 2"])

    def test_a_respawn_or_an_exit_fails(self):
        respawned = [row(2, "5", "400.0", "400.0"), row(3, "6", "300.0", "300.0")]
        failures, _ = soak_report.verdict(respawned, GOOD_PLAYER, warmup=2, max_growth=10)
        self.assertEqual(len(failures), 1)
        self.assertIn("m exited or was respawned", failures[0])
        gone = [row(2, "5", "400.0", "400.0"), row(3, "gone", "gone", "gone"), row(4, "5", "400.0", "400.0")]
        failures, _ = soak_report.verdict(gone, GOOD_PLAYER, warmup=2, max_growth=10)
        self.assertIn("m exited or was respawned", failures[0])

    def test_a_frame_set_not_fused_lost_or_timed_out_fails(self):
        rows = [row(2, "5", "400.0", "400.0"), row(3, "5", "400.0", "400.0")]
        player = dict(GOOD_PLAYER, fused="119", timed_out="1")
        failures, _ = soak_report.verdict(rows, player, warmup=2, max_growth=10)
        self.assertEqual(failures, ["player: timed_out 1", "player: 120 frame sets played but 119 fused"])
        player = dict(GOOD_PLAYER, fused="119", lost="1")  # dropped on the way to the fusion stage
        failures, _ = soak_report.verdict(rows, player, warmup=2, max_growth=10)
        self.assertEqual(failures, ["player: lost 1", "player: 120 frame sets played but 119 fused"])
        failures, _ = soak_report.verdict(rows, None, warmup=2, max_growth=10)
        self.assertEqual(failures, ["the player wrote no summary (see launch.log)"])

    def test_too_few_samples_fail(self):
        failures, _ = soak_report.verdict([row(1, "5", "400.0", "400.0")], GOOD_PLAYER, warmup=2, max_growth=10)
        self.assertEqual(failures, ["too few samples (1) for a growth after minute 2"])


if __name__ == "__main__":
    unittest.main()
