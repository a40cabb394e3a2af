"""scripts/eval/road_depth.py: its pixel rays against the camera models' forward projections, by hand."""
import os
import sys
import unittest

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "scripts", "eval"))
import road_depth  # noqa: E402


def project_omni(X, xi, fu, fv, pu, pv, k1, k2, p1, p2):
    """Kalibr omni-radtan: X on the unit sphere, shifted by xi, to the normalized plane, distorted, to pixels."""
    Xs = X / np.linalg.norm(X)
    x, y = Xs[0] / (Xs[2] + xi), Xs[1] / (Xs[2] + xi)
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2 * r2
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return fu * xd + pu, fv * yd + pv


class Rays(unittest.TestCase):
    def check(self, cam, xi, coeffs):
        """Each pixel's ray, projected by the model's definition, lands on that pixel."""
        rays = road_depth.rays_of(cam)
        fu, fv, pu, pv = cam['intrinsics'][-4:]
        w, h = cam['resolution']
        rng = np.random.default_rng(3)
        checked = 0
        for _ in range(500):
            u, v = int(rng.integers(0, w)), int(rng.integers(0, h))
            X = rays[v, u]
            if np.isnan(X).any():
                continue
            self.assertAlmostEqual(np.linalg.norm(X), 1.0, places=9)
            pu_, pv_ = project_omni(X, xi, fu, fv, pu, pv, *coeffs)
            self.assertLess(abs(pu_ - u) + abs(pv_ - v), 1e-3, (u, v, pu_, pv_))
            checked += 1
        self.assertGreater(checked, 300)

    def test_omni_with_xi_2_8_as_the_surround_rig(self):
        cam = {'camera_model': 'omni', 'intrinsics': [2.8, 2600.0, 2600.0, 959.5, 603.5],
               'distortion_model': 'radtan', 'distortion_coeffs': [0.0, 0.0, 0.0, 0.0], 'resolution': [1920, 1208]}
        self.check(cam, 2.8, (0.0, 0.0, 0.0, 0.0))

    def test_omni_with_radtan_as_the_default_rig(self):
        coeffs = (-0.02, 0.004, 0.0002, -0.0001)
        cam = {'camera_model': 'omni', 'intrinsics': [0.98, 520.0, 520.0, 511.5, 271.5],
               'distortion_model': 'radtan', 'distortion_coeffs': list(coeffs), 'resolution': [1024, 544]}
        self.check(cam, 0.98, coeffs)

    def test_pinhole(self):
        cam = {'camera_model': 'pinhole', 'intrinsics': [200.0, 200.0, 319.0, 239.0], 'resolution': [640, 480]}
        rays = road_depth.rays_of(cam)
        # The pixel 200 px right of the centre looks 45 deg to the right, 200 px down 45 deg down.
        np.testing.assert_allclose(rays[239, 519], np.array([1.0, 0.0, 1.0]) / np.sqrt(2), atol=1e-12)
        np.testing.assert_allclose(rays[439, 319], np.array([0.0, 1.0, 1.0]) / np.sqrt(2), atol=1e-12)

    def test_pixels_beyond_the_omni_field_of_view_have_no_ray(self):
        cam = {'camera_model': 'omni', 'intrinsics': [2.8, 2600.0, 2600.0, 959.5, 603.5],
               'distortion_coeffs': [0.0] * 4, 'resolution': [1920, 1208]}
        rays = road_depth.rays_of(cam)
        # r^2 (1 - xi^2) + 1 < 0 beyond r = 1 / sqrt(xi^2 - 1) = 0.382 (993 px): the corners.
        self.assertTrue(np.isnan(rays[0, 0]).all())
        self.assertFalse(np.isnan(rays[603, 959]).any())

    def test_an_unknown_model_is_refused_by_name(self):
        with self.assertRaises(SystemExit) as e:
            road_depth.rays_of({'camera_model': 'eucm', 'intrinsics': [1, 1, 1, 1, 1], 'resolution': [4, 4]})
        self.assertIn("eucm", str(e.exception))


if __name__ == "__main__":
    unittest.main()
