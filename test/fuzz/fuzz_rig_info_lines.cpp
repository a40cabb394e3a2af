// libFuzzer target: rig_info's --project / --unproject line filter
// (rig_info::filterLine, rig_info::readLine), on one camera of each model.
// The first input byte picks the camera and the direction; the rest is the
// input text, read line by line as rig_info does. Each answer must be
// "invalid" or finite numbers: a pixel inside the image for --project, a unit
// ray for --unproject.
#define FM_RIG_INFO_NO_MAIN
#include "../../src/tools/rig_info.cpp"

#include <cstdint>
#include <sstream>

namespace {

fm::Intrinsics intr(double f, double cx, double cy, int w, int h) {
  fm::Intrinsics in;
  in.width = w, in.height = h, in.fx = f, in.fy = f, in.cx = cx, in.cy = cy;
  return in;
}

const std::vector<fm::CameraModel>& cameras() {
  static const std::vector<fm::CameraModel> c = {
      fm::CameraModel::unified(intr(300, 512, 272, 1024, 544), 1.0),
      fm::CameraModel::unified(intr(520, 511.5, 271.5, 1024, 544), 0.98, -0.02, 0.004, 2e-4, -1e-4),
      fm::CameraModel::doubleSphere(intr(350, 511.5, 271.5, 1024, 544), -0.18, 0.59),
      fm::CameraModel::kannalaBrandt(intr(330, 511.5, 271.5, 1024, 544), 0.02, -0.005, 0.001, -0.0002),
      fm::CameraModel::pinhole(intr(400, 320, 240, 640, 480), -0.28, 0.07, 1e-3, -5e-4),
  };
  return c;
}

[[noreturn]] void finding(const std::string& what, const std::string& line, const std::string& out) {
  std::fprintf(stderr, "fuzz_rig_info_lines: %s: line '%s' -> '%s'\n", what.c_str(), line.c_str(), out.c_str());
  std::abort();
}

}  // namespace

// The normal suite (test/test_fuzz_regressions.cpp) links this file with the
// entry point renamed by FM_FUZZ_ENTRY and replays test/fuzz/<target>/.
#ifndef FM_FUZZ_ENTRY
#define FM_FUZZ_ENTRY LLVMFuzzerTestOneInput
#endif
extern "C" int FM_FUZZ_ENTRY(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const auto& cams = cameras();
  const fm::CameraModel& cam = cams[data[0] % cams.size()];
  const bool project = (data[0] / cams.size()) % 2 == 0;
  std::istringstream in(std::string(reinterpret_cast<const char*>(data + 1), size - 1));
  std::string line;
  bool too_long = false;
  while (rig_info::readLine(in, &line, &too_long)) {
    if (line.size() > rig_info::kMaxLineLength) finding("line longer than the limit", "", "");
    bool parsed = false;
    const std::string out = rig_info::filterLine(cam, project, line, &parsed);
    if (out == "invalid") continue;
    if (!parsed) finding("an answer to an unparsed line", line, out);
    std::istringstream ss(out);
    std::vector<double> v;
    for (double x; ss >> x;) v.push_back(x);
    if (v.size() != (project ? 2u : 3u)) finding("wrong count of numbers", line, out);
    for (double x : v)
      if (!std::isfinite(x)) finding("non-finite answer", line, out);
    if (project && !cam.isInImage(Eigen::Vector2d(v[0], v[1]), -1e-6)) finding("pixel outside the image", line, out);
    if (!project && std::abs(std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) - 1.0) > 1e-6)
      finding("ray not of unit length", line, out);
  }
  return 0;
}
