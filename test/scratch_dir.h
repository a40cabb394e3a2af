// A test's scratch directory under /tmp, removed with everything in it when
// the object goes (a test's end, or the process's end for a static one), so
// that the suite leaves nothing behind.
#ifndef FISHEYE_MAPPING_TEST_SCRATCH_DIR_H_
#define FISHEYE_MAPPING_TEST_SCRATCH_DIR_H_

#include <stdlib.h>

#include <filesystem>
#include <stdexcept>
#include <string>
#include <system_error>
#include <vector>

namespace fisheye_mapping {
namespace test {

class ScratchDir {
 public:
  explicit ScratchDir(const std::string& prefix) {
    std::vector<char> tmpl(prefix.begin(), prefix.end());
    const std::string suffix = "XXXXXX";
    tmpl.insert(tmpl.end(), suffix.begin(), suffix.end());
    tmpl.push_back('\0');
    if (!mkdtemp(tmpl.data())) throw std::runtime_error("cannot make a scratch directory " + prefix + "XXXXXX");
    path_ = tmpl.data();
  }
  ~ScratchDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

// A fresh directory inside a program-wide scratch directory made with
// `prefix` at the first call (removed when the program ends): 0, 1, 2, ...
inline std::string freshScratchSubdir(const std::string& prefix) {
  static const ScratchDir root(prefix);
  static int n = 0;
  const std::string d = root.path() + "/" + std::to_string(n++);
  std::filesystem::create_directories(d);
  return d;
}

}  // namespace test
}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_TEST_SCRATCH_DIR_H_
