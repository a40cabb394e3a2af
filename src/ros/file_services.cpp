#include "fisheye_mapping/ros/file_services.h"

#include <std_srvs/Trigger.h>

#include "fisheye_mapping/ros/tsdf_node_helpers.h"

namespace fisheye_mapping {

void FilePathServices::add(const std::string& name, const std::string& what, Access access,
                           std::function<void(const std::string& path)> fn) {
  using Req = fisheye_mapping::FilePath::Request;
  using Res = fisheye_mapping::FilePath::Response;
  servers_.push_back(pnh_.advertiseService<Req, Res>(name, [this, what, access, fn](Req& req, Res& res) {
    run(res, req.path, what, access, fn);
    return true;
  }));
}

void FilePathServices::addTrigger(const std::string& name, const std::string& what, std::function<void()> fn) {
  using Req = std_srvs::Trigger::Request;
  using Res = std_srvs::Trigger::Response;
  servers_.push_back(pnh_.advertiseService<Req, Res>(name, [this, what, fn](Req&, Res& res) {
    std::lock_guard<std::mutex> lock(mutex_);
    res.success = false;
    if (!ready_()) return res.message = "the stage did not start (see its error log)", true;
    try {
      fn();
      res.success = true;
      res.message = what + ": done";
      log_(false, res.message);
    } catch (const std::exception& e) {
      res.message = what + " failed: " + e.what();
      log_(true, res.message + " (" + std::to_string(++failures_) + " failed requests so far)");
    }
    return true;
  }));
}

void FilePathServices::run(fisheye_mapping::FilePath::Response& res, const std::string& requested,
                           const std::string& what, Access access, const std::function<void(const std::string&)>& fn) {
  std::lock_guard<std::mutex> lock(mutex_);
  res.success = false;
  if (!ready_()) {
    res.message = "the stage did not start (see its error log)";
    return;
  }
  try {
    const std::string path = access == Access::kSave ? confineSavePath(requested, folder_)
                                                     : tsdf_node::inputPath(requested, folder_);
    fn(path);
    res.success = true;
    res.message = what + " " + path + ": done";
    log_(false, res.message);
  } catch (const std::exception& e) {
    res.message = what + " '" + requested + "' failed: " + e.what();
    log_(true, res.message + " (" + std::to_string(++failures_) + " failed requests so far)");
  } catch (...) {
    res.message = what + " '" + requested + "' failed: unknown exception";
    log_(true, res.message + " (" + std::to_string(++failures_) + " failed requests so far)");
  }
}

}  // namespace fisheye_mapping
