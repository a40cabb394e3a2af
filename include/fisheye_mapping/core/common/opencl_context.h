// OpenCL device selection, program building and caching for the core.
//
// Programs are built from embedded source text (see clSource); the first build
// of a given source set and options is cached for the context's lifetime.
// Not thread-safe: use one context per thread, or guard it.
#ifndef FISHEYE_MAPPING_CORE_COMMON_OPENCL_CONTEXT_H_
#define FISHEYE_MAPPING_CORE_COMMON_OPENCL_CONTEXT_H_

#define CL_HPP_TARGET_OPENCL_VERSION 120
#define CL_HPP_MINIMUM_OPENCL_VERSION 120
#define CL_HPP_ENABLE_EXCEPTIONS
#if __has_include(<CL/opencl.hpp>)
#include <CL/opencl.hpp>
#else  // Ubuntu 20.04's opencl-clhpp-headers ships only the older name
#include <CL/cl2.hpp>
#endif

#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace fisheye_mapping {

class OpenClError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Text of a file OpenCL programs are built from ("camera_model_shared.h", ...),
// embedded at build time. When the environment variable FISHEYE_MAPPING_CL_DIR
// names a folder holding a file of that name, that file is read instead, so
// kernels can be edited without rebuilding. Throws OpenClError for unknown names.
std::string clSource(const std::string& name);

class OpenClContext {
 public:
  // device: "" picks the first GPU, else the first device of any type;
  // otherwise a case-insensitive substring of "<platform> / <device>" names, or
  // an index "0", "1", ... into listDevices(). Throws OpenClError when nothing
  // matches (the message lists the devices found).
  explicit OpenClContext(const std::string& device = "");

  // "<platform> / <device>" for every OpenCL device on the machine.
  static std::vector<std::string> listDevices();
  // Whether any OpenCL device on the machine is a GPU (never throws).
  static bool hasGpu();

  // Builds (or returns the cached) program made of the given sources,
  // concatenated in order. Throws OpenClError carrying the build log.
  cl::Program& program(const std::vector<std::string>& sources, const std::string& options = "");

  const cl::Context& context() const { return context_; }
  const cl::Device& device() const { return device_; }
  cl::CommandQueue& queue() { return queue_; }
  const std::string& deviceName() const { return name_; }

 private:
  cl::Context context_;
  cl::Device device_;
  cl::CommandQueue queue_;
  std::string name_;
  std::map<std::string, cl::Program> programs_;
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_COMMON_OPENCL_CONTEXT_H_
