"""scripts/eval/trail_points.py: trail points of hand-made clouds against a hand-made scene, read from the files
make_drive and offline_mapper write (binary PLY triangles, binary PCD)."""
import os
import struct
import sys
import tempfile
import unittest

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "scripts", "eval"))
import trail_points  # noqa: E402


def write_ply(path, vertices, triangles):
    with open(path, "wb") as f:
        f.write(b"ply\nformat binary_little_endian 1.0\ncomment PCL generated\n")
        f.write(f"element vertex {len(vertices)}\nproperty float x\nproperty float y\nproperty float z\n".encode())
        f.write(f"element face {len(triangles)}\nproperty list uchar int vertex_indices\nend_header\n".encode())
        f.write(np.asarray(vertices, "<f4").tobytes())
        for t in triangles:
            f.write(struct.pack("<B3i", 3, *t))


def write_pcd(path, points):
    """x y z and an intensity field, as offline_mapper's cloud.pcd."""
    p = np.asarray(points, np.float32)
    with open(path, "wb") as f:
        f.write(b"# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z intensity\n")
        f.write(f"SIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH {len(p)}\nHEIGHT 1\n".encode())
        f.write(f"VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(p)}\nDATA binary\n".encode())
        f.write(np.hstack([p, np.full((len(p), 1), 0.5, np.float32)]).tobytes())


class TrailPoints(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.TemporaryDirectory()
        # The scene: the square [0, 10] x [0, 10] of the plane z = 0, two triangles.
        self.scene = os.path.join(self.dir.name, "scene.ply")
        write_ply(self.scene, [[0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0]], [[0, 1, 2], [0, 2, 3]])

    def tearDown(self):
        self.dir.cleanup()

    def test_points_farther_than_tol_from_the_scene_are_trail_points(self):
        v, t = trail_points.read_ply(self.scene)
        self.assertEqual(v.shape, (4, 3))
        tree = trail_points.cKDTree(trail_points.sample_mesh(v, t))
        # 0.1 and 0.2 m above the square: on the scene; 0.4 and 1 m above it, and
        # 0.4 m beyond its edge at z = 0: trail points (tolerance 0.25 m).
        cloud = np.array([[5, 5, 0.1], [2, 7, 0.2], [5, 5, 0.4], [3, 3, 1.0], [10.4, 5, 0.0]])
        path = os.path.join(self.dir.name, "a.pcd")
        write_pcd(path, cloud)
        read = trail_points.read_pcd(path)
        np.testing.assert_allclose(read, cloud, atol=1e-6)
        trail = trail_points.trail_points(tree, read, 0.25)
        np.testing.assert_allclose(trail, cloud[2:], atol=1e-6)

    def test_only_in_and_cells(self):
        a = np.array([[1.0, 1.0, 1.0], [1.2, 1.0, 1.0], [7.0, 7.0, 2.0]])
        b = np.array([[1.1, 1.3, 1.0]])
        only = trail_points.only_in(a, b, 0.5)  # (7, 7) has nothing of b within 0.5 m
        np.testing.assert_allclose(only, a[2:])
        self.assertEqual(len(trail_points.only_in(b, a, 0.5)), 0)
        c = trail_points.cells(a, size=3.0)
        self.assertEqual([(x, y, n) for x, y, n, _, _ in c], [(1.5, 1.5, 2), (7.5, 7.5, 1)])
        self.assertEqual((c[0][3], c[0][4]), (1.0, 1.0))

    def test_a_text_ply_is_refused_naming_the_file(self):
        path = os.path.join(self.dir.name, "text.ply")
        with open(path, "w") as f:
            f.write("ply\nformat ascii 1.0\nelement vertex 0\nend_header\n")
        with self.assertRaises(SystemExit) as e:
            trail_points.read_ply(path)
        self.assertIn("text.ply", str(e.exception))


if __name__ == "__main__":
    unittest.main()
