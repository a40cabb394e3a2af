// The shared camera-model header compiled as OpenCL C and run on the OpenCL
// device (PoCL's CPU device here): same validity, same pixels and rays as the
// C++ double-precision path, to float precision.
#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "fisheye_mapping/core/common/opencl_context.h"
#include "test_utils.h"

namespace fisheye_mapping {
namespace {

const char* kKernels = R"CL(
__kernel void project_points(__global const struct FmCameraT* cam_in, __global const float* xyz,
                             __global float* uv, __global int* valid) {
  const int i = get_global_id(0);
  FmCamera cam = *cam_in;
  float u, v;
  valid[i] = fm_project(&cam, xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2], &u, &v);
  uv[2 * i] = u;
  uv[2 * i + 1] = v;
}
__kernel void unproject_pixels(__global const struct FmCameraT* cam_in, __global const float* uv,
                               __global float* ray, __global int* valid) {
  const int i = get_global_id(0);
  FmCamera cam = *cam_in;
  float x, y, z;
  valid[i] = fm_unproject(&cam, uv[2 * i], uv[2 * i + 1], &x, &y, &z);
  ray[3 * i] = x;
  ray[3 * i + 1] = y;
  ray[3 * i + 2] = z;
}
)CL";

class OpenClCameraModel : public ::testing::Test {
 protected:
  void SetUp() override {
    if (OpenClContext::listDevices().empty()) GTEST_SKIP() << "no OpenCL device on this machine";
    ctx_ = std::make_unique<OpenClContext>();
  }
  std::unique_ptr<OpenClContext> ctx_;
};

TEST_F(OpenClCameraModel, KernelsAgreeWithCpp) {
  cl::Program& program = ctx_->program({clSource("camera_model_shared.h"), kKernels});
  std::cout << "OpenCL device: " << ctx_->deviceName() << std::endl;
  for (const auto& [name, cam] : test::realisticCameras()) {
    // Points over 98% of the valid cone; pixels over the image.
    std::vector<float> xyz;
    const double max_angle = std::min(cam.maxValidAngle(), M_PI) * 0.98;
    for (int i = 0; i <= 40; ++i) {
      for (int j = 0; j < 16; ++j) {
        const double t = max_angle * i / 40.0, p = 2 * M_PI * j / 16.0;
        xyz.insert(xyz.end(), {float(2.5 * std::sin(t) * std::cos(p)),
                               float(2.5 * std::sin(t) * std::sin(p)), float(2.5 * std::cos(t))});
      }
    }
    std::vector<float> pixels;
    for (int v = 0; v < cam.height(); v += 17) {
      for (int u = 0; u < cam.width(); u += 13) pixels.insert(pixels.end(), {u + 0.5f, v + 0.25f});
    }
    const size_t n_pts = xyz.size() / 3, n_px = pixels.size() / 2;

    const FmCameraT<float> params = cam.floatParams();
    const cl::Context& c = ctx_->context();
    cl::Buffer cam_buf(c, CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, sizeof(params),
                       const_cast<FmCameraT<float>*>(&params));
    cl::Buffer xyz_buf(c, CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, xyz.size() * 4, xyz.data());
    cl::Buffer uv_out(c, CL_MEM_WRITE_ONLY, n_pts * 2 * 4);
    cl::Buffer valid_pts(c, CL_MEM_WRITE_ONLY, n_pts * 4);
    cl::Buffer px_buf(c, CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, pixels.size() * 4, pixels.data());
    cl::Buffer ray_out(c, CL_MEM_WRITE_ONLY, n_px * 3 * 4);
    cl::Buffer valid_px(c, CL_MEM_WRITE_ONLY, n_px * 4);

    cl::Kernel project(program, "project_points");
    project.setArg(0, cam_buf), project.setArg(1, xyz_buf), project.setArg(2, uv_out),
        project.setArg(3, valid_pts);
    cl::Kernel unproject(program, "unproject_pixels");
    unproject.setArg(0, cam_buf), unproject.setArg(1, px_buf), unproject.setArg(2, ray_out),
        unproject.setArg(3, valid_px);
    auto& q = ctx_->queue();
    q.enqueueNDRangeKernel(project, cl::NullRange, cl::NDRange(n_pts));
    q.enqueueNDRangeKernel(unproject, cl::NullRange, cl::NDRange(n_px));
    std::vector<float> uv(n_pts * 2), ray(n_px * 3);
    std::vector<int> vp(n_pts), vx(n_px);
    q.enqueueReadBuffer(uv_out, CL_TRUE, 0, uv.size() * 4, uv.data());
    q.enqueueReadBuffer(valid_pts, CL_TRUE, 0, vp.size() * 4, vp.data());
    q.enqueueReadBuffer(ray_out, CL_TRUE, 0, ray.size() * 4, ray.data());
    q.enqueueReadBuffer(valid_px, CL_TRUE, 0, vx.size() * 4, vx.data());

    int compared_pts = 0, compared_px = 0;
    for (size_t i = 0; i < n_pts; ++i) {
      Eigen::Vector2d ref;
      const bool ok = cam.project(Eigen::Vector3d(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]), &ref);
      ASSERT_EQ(ok, vp[i] != 0) << name << " point " << i;
      // Float pixels lose precision far outside the image (pinhole near 90 deg).
      if (!ok || !cam.isInImage(ref, -cam.width())) continue;
      EXPECT_NEAR(uv[2 * i], ref.x(), 2e-3) << name << " point " << i;
      EXPECT_NEAR(uv[2 * i + 1], ref.y(), 2e-3) << name << " point " << i;
      ++compared_pts;
    }
    for (size_t i = 0; i < n_px; ++i) {
      Eigen::Vector3d ref;
      const bool ok = cam.unproject(Eigen::Vector2d(pixels[2 * i], pixels[2 * i + 1]), &ref);
      ASSERT_EQ(ok, vx[i] != 0) << name << " pixel " << i;
      if (!ok) continue;
      EXPECT_LT((Eigen::Vector3d(ray[3 * i], ray[3 * i + 1], ray[3 * i + 2]) - ref).norm(), 2e-5)
          << name << " pixel " << i;
      ++compared_px;
    }
    EXPECT_GT(compared_pts, 300) << name;
    EXPECT_GT(compared_px, 1000) << name;
  }
}

TEST_F(OpenClCameraModel, BuildErrorsCarryTheLog) {
  try {
    ctx_->program({clSource("camera_model_shared.h"), "__kernel void k() { undefined_fn(); }"});
    FAIL() << "a broken kernel built";
  } catch (const OpenClError& e) {
    EXPECT_NE(std::string(e.what()).find("undefined_fn"), std::string::npos) << e.what();
  }
}

TEST(OpenClContext, UnknownDeviceNamesTheDevicesFound) {
  if (OpenClContext::listDevices().empty()) GTEST_SKIP() << "no OpenCL device on this machine";
  try {
    OpenClContext ctx("no-such-device-xyz");
    FAIL();
  } catch (const OpenClError& e) {
    EXPECT_NE(std::string(e.what()).find("no-such-device-xyz"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find(OpenClContext::listDevices()[0]), std::string::npos);
  }
}

}  // namespace
}  // namespace fisheye_mapping
