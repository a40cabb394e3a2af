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
    res.success = attempt(&res.message, what + " failed", [&] {
      fn();
      return what + ": done";
    });
    return true;
  }));
}

void FilePathServices::run(fisheye_mapping::FilePath::Response& res, const std::string& requested,
                           const std::string& what, Access access, const std::function<void(const std::string&)>& fn) {
  res.success = attempt(&res.message, what + " '" + requested + "' failed", [&] {
    const std::string path = access == Access::kSave ? confineSavePath(requested, folder_)
                                                     : tsdf_node::inputPath(requested, folder_);
    fn(path);
    return what + " " + path + ": done";
  });
}

bool FilePathServices::attempt(std::string* reply, const std::string& failure,
                               const std::function<std::string()>& fn) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!ready_()) {
    *reply = "the stage did not start (see its error log)";
    return false;
  }
  try {
    *reply = fn();
    log_(false, *reply);
    return true;
  } catch (const std::exception& e) {
    *reply = failure + ": " + e.what();
  } catch (...) {
    *reply = failure + ": unknown exception";
  }
  log_(true, *reply + " (" + std::to_string(++failures_) + " failed requests so far)");
  return false;
}

}  // namespace fisheye_mapping
