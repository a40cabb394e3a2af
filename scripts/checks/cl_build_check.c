/* Builds every OpenCL program variant the core uses (the plane sweep for 1-4
 * supporting views, window radius 1-5, each camera model fixed or generic;
 * the TSDF integrator) on every OpenCL device found, with the host code's
 * sources and options (-cl-std=CL1.2), and creates each kernel. Prints one
 * line per device and exits 1 naming the first variant that fails, with the
 * driver's build log. No ROS, OpenCV or project library: it compiles with a C
 * compiler and the OpenCL headers alone, so it runs on a GPU machine that has
 * nothing else (scripts/checks/cl_build_check builds and runs it).
 *
 *   cl_build_check SRC_ROOT     (the repository root) */
#define CL_TARGET_OPENCL_VERSION 120
#include <CL/cl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static char* slurp(const char* root, const char* rel) {
  char path[4096];
  snprintf(path, sizeof path, "%s/%s", root, rel);
  FILE* f = fopen(path, "rb");
  if (!f) { fprintf(stderr, "cl_build_check: cannot read %s\n", path); exit(2); }
  fseek(f, 0, SEEK_END);
  long n = ftell(f);
  fseek(f, 0, SEEK_SET);
  char* s = malloc((size_t)n + 1);
  if (fread(s, 1, (size_t)n, f) != (size_t)n) { fprintf(stderr, "cl_build_check: short read %s\n", path); exit(2); }
  s[n] = 0;
  fclose(f);
  return s;
}

/* Builds sources with options on dev and creates the named kernels; 0 on success. */
static int build(cl_context ctx, cl_device_id dev, const char** src, int nsrc, const char* options,
                 const char** kernels, int nk, const char* what) {
  cl_int err;
  cl_program p = clCreateProgramWithSource(ctx, (cl_uint)nsrc, src, NULL, &err);
  if (err != CL_SUCCESS) { printf("  %s: clCreateProgramWithSource error %d\n", what, err); return 1; }
  char opts[1024];
  snprintf(opts, sizeof opts, "%s -cl-std=CL1.2", options);
  err = clBuildProgram(p, 1, &dev, opts, NULL, NULL);
  if (err != CL_SUCCESS) {
    size_t n = 0;
    clGetProgramBuildInfo(p, dev, CL_PROGRAM_BUILD_LOG, 0, NULL, &n);
    char* log = malloc(n + 1);
    clGetProgramBuildInfo(p, dev, CL_PROGRAM_BUILD_LOG, n, log, NULL);
    log[n] = 0;
    printf("  %s [%s]: build error %d:\n%s\n", what, opts, err, log);
    free(log);
    clReleaseProgram(p);
    return 1;
  }
  for (int i = 0; i < nk; ++i) {
    cl_kernel k = clCreateKernel(p, kernels[i], &err);
    if (err != CL_SUCCESS) { printf("  %s [%s]: no kernel %s (error %d)\n", what, opts, kernels[i], err); clReleaseProgram(p); return 1; }
    clReleaseKernel(k);
  }
  clReleaseProgram(p);
  return 0;
}

int main(int argc, char** argv) {
  if (argc != 2) { fprintf(stderr, "usage: cl_build_check SRC_ROOT\n"); return 2; }
  const char* root = argv[1];
  const char* cam = slurp(root, "include/fisheye_mapping/core/camera/camera_model_shared.h");
  const char* sweep_src[3] = {cam, slurp(root, "include/fisheye_mapping/core/depth/plane_sweep_shared.h"),
                              slurp(root, "src/core/depth/plane_sweep.cl")};
  const char* tsdf_src[3] = {cam, slurp(root, "include/fisheye_mapping/core/tsdf/tsdf_shared.h"),
                             slurp(root, "src/core/tsdf/tsdf_integrate.cl")};
  const char* sweep_k[3] = {"sweep_warp", "sweep_cost", "sweep_select"};
  const char* tsdf_k[1] = {"integrate_blocks"};
  cl_platform_id plats[16];
  cl_uint np = 0;
  if (clGetPlatformIDs(16, plats, &np) != CL_SUCCESS || np == 0) { printf("cl_build_check: no OpenCL platform\n"); return 1; }
  int devices = 0, failed = 0;
  for (cl_uint pi = 0; pi < np; ++pi) {
    cl_device_id devs[16];
    cl_uint nd = 0;
    if (clGetDeviceIDs(plats[pi], CL_DEVICE_TYPE_ALL, 16, devs, &nd) != CL_SUCCESS) continue;
    for (cl_uint di = 0; di < nd; ++di) {
      char name[256] = "", version[256] = "", driver[256] = "";
      cl_device_type type;
      clGetDeviceInfo(devs[di], CL_DEVICE_NAME, sizeof name, name, NULL);
      clGetDeviceInfo(devs[di], CL_DEVICE_VERSION, sizeof version, version, NULL);
      clGetDeviceInfo(devs[di], CL_DRIVER_VERSION, sizeof driver, driver, NULL);
      clGetDeviceInfo(devs[di], CL_DEVICE_TYPE, sizeof type, &type, NULL);
      cl_int err;
      cl_context ctx = clCreateContext(NULL, 1, &devs[di], NULL, NULL, &err);
      if (err != CL_SUCCESS) { printf("%s: clCreateContext error %d\n", name, err); ++failed; continue; }
      ++devices;
      int variants = 0, bad = 0;
      char opts[256];
      for (int views = 1; views <= 4 && !bad; ++views)
        for (int radius = 1; radius <= 5 && !bad; ++radius)
          for (int model = -1; model <= 3 && !bad; ++model) {
            int n = snprintf(opts, sizeof opts, "-DFM_CAM_SPACE=__global -DFM_SWEEP_VIEWS=%d -DFM_SWEEP_RADIUS=%d", views, radius);
            if (model >= 0) snprintf(opts + n, sizeof opts - (size_t)n, " -DFM_FIXED_MODEL=%d", model);
            bad |= build(ctx, devs[di], sweep_src, 3, opts, sweep_k, 3, "plane_sweep.cl");
            ++variants;
          }
      if (!bad) { bad |= build(ctx, devs[di], tsdf_src, 3, "", tsdf_k, 1, "tsdf_integrate.cl"); ++variants; }
      printf("%s %s (%s, %s, driver %s): %s, %d program variants built\n", (type & CL_DEVICE_TYPE_GPU) ? "GPU" : "device",
             name, version, (type & CL_DEVICE_TYPE_GPU) ? "gpu" : "not gpu", driver, bad ? "FAILED" : "ok", variants);
      failed += bad;
      clReleaseContext(ctx);
    }
  }
  if (devices == 0) { printf("cl_build_check: no usable OpenCL device\n"); return 1; }
  return failed ? 1 : 0;
}
