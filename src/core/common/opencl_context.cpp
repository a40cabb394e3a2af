#include "fisheye_mapping/core/common/opencl_context.h"

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <fstream>
#include <sstream>

namespace fisheye_mapping {

const std::map<std::string, std::string>& embeddedClSources();  // generated

namespace {

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

struct DeviceEntry {
  cl::Platform platform;
  cl::Device device;
  std::string name;
};

std::vector<DeviceEntry> allDevices() {
  std::vector<DeviceEntry> out;
  std::vector<cl::Platform> platforms;
  try {
    cl::Platform::get(&platforms);
  } catch (const cl::Error&) {
    return out;  // no ICD loader platform at all
  }
  for (auto& platform : platforms) {
    std::vector<cl::Device> devices;
    try {
      platform.getDevices(CL_DEVICE_TYPE_ALL, &devices);
    } catch (const cl::Error&) {
      continue;
    }
    for (auto& device : devices) {
      out.push_back({platform, device,
                     platform.getInfo<CL_PLATFORM_NAME>() + " / " + device.getInfo<CL_DEVICE_NAME>()});
    }
  }
  return out;
}

}  // namespace

std::string clSource(const std::string& name) {
  if (const char* dir = std::getenv("FISHEYE_MAPPING_CL_DIR")) {
    std::ifstream f(std::string(dir) + "/" + name);
    if (f) {
      std::stringstream ss;
      ss << f.rdbuf();
      return ss.str();
    }
  }
  const auto& sources = embeddedClSources();
  const auto it = sources.find(name);
  if (it == sources.end()) throw OpenClError("no embedded OpenCL source named '" + name + "'");
  return it->second;
}

bool OpenClContext::hasGpu() {
  for (const auto& d : allDevices()) {
    try {
      if (d.device.getInfo<CL_DEVICE_TYPE>() & CL_DEVICE_TYPE_GPU) return true;
    } catch (const cl::Error&) {
    }
  }
  return false;
}

std::vector<std::string> OpenClContext::listDevices() {
  std::vector<std::string> names;
  for (const auto& d : allDevices()) names.push_back(d.name);
  return names;
}

OpenClContext::OpenClContext(const std::string& device) {
  const auto devices = allDevices();
  if (devices.empty()) {
    throw OpenClError("no OpenCL device found (is an ICD such as pocl-opencl-icd installed?)");
  }
  const DeviceEntry* chosen = nullptr;
  if (device.empty()) {
    for (const auto& d : devices) {
      if (d.device.getInfo<CL_DEVICE_TYPE>() & CL_DEVICE_TYPE_GPU) {
        chosen = &d;
        break;
      }
    }
    if (!chosen) chosen = &devices.front();
  } else if (std::all_of(device.begin(), device.end(), ::isdigit)) {
    const size_t index = std::stoul(device);
    if (index < devices.size()) chosen = &devices[index];
  } else {
    for (const auto& d : devices) {
      if (lower(d.name).find(lower(device)) != std::string::npos) {
        chosen = &d;
        break;
      }
    }
  }
  if (!chosen) {
    std::string known;
    for (size_t i = 0; i < devices.size(); ++i) known += "\n  " + std::to_string(i) + ": " + devices[i].name;
    throw OpenClError("no OpenCL device matches '" + device + "'; devices found:" + known);
  }
  device_ = chosen->device;
  name_ = chosen->name;
  context_ = cl::Context(device_);
  queue_ = cl::CommandQueue(context_, device_);
}

cl::Program& OpenClContext::program(const std::vector<std::string>& sources,
                                    const std::string& options) {
  std::string key = options;
  for (const auto& s : sources) key += '\x1f' + s;
  auto it = programs_.find(key);
  if (it != programs_.end()) return it->second;
  cl::Program::Sources srcs(sources.begin(), sources.end());
  cl::Program program(context_, srcs);
  try {
    program.build({device_}, (options + " -cl-std=CL1.2").c_str());
  } catch (const cl::Error&) {
    const std::string log = program.getBuildInfo<CL_PROGRAM_BUILD_LOG>(device_);
    throw OpenClError("OpenCL program failed to build on " + name_ + ":\n" + log);
  }
  return programs_.emplace(key, program).first->second;
}

}  // namespace fisheye_mapping
