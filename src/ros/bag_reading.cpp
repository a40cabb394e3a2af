// Opening bags cut short (see include/fisheye_mapping/ros/bag_reading.h).
#include "fisheye_mapping/ros/bag_reading.h"

#include <cstdint>
#include <cstring>
#include <fstream>
#include <stdexcept>
#include <string>

#include <set>

#include <rosbag/view.h>

#include "fisheye_mapping/core/common/safe_open.h"
#include "fisheye_mapping/ros/conversions.h"

namespace fisheye_mapping {
namespace {

constexpr char kMagic[] = "#ROSBAG V2.0\n";
constexpr std::size_t kMagicLength = sizeof(kMagic) - 1;
constexpr std::uint32_t kMaxFileHeaderBytes = 1u << 16;  // rosbag writes about 70

std::uint64_t littleEndian(const char* p, int bytes) {
  std::uint64_t v = 0;
  for (int i = bytes - 1; i >= 0; --i) v = (v << 8) | static_cast<unsigned char>(p[i]);
  return v;
}

}  // namespace

std::string bagIndexProblem(const std::string& path) {
  std::uint64_t size = 0;
  if (!regularFileProblem(path, kNoSizeLimit, &size).empty()) return "";
  std::ifstream f(path, std::ios::binary);
  char magic[kMagicLength] = {};
  char len[4] = {};
  if (!f.read(magic, kMagicLength) || std::memcmp(magic, kMagic, kMagicLength) != 0) return "";
  if (!f.read(len, 4)) return "it is cut short: the file ends inside its header";
  const std::uint32_t header_len = std::uint32_t(littleEndian(len, 4));
  if (header_len > kMaxFileHeaderBytes) return "";  // not what rosbag writes: librosbag names it
  std::string header(header_len, '\0');
  if (!f.read(&header[0], header_len)) return "it is cut short: the file ends inside its header";
  // Fields: a 4-byte length, then name=value.
  for (std::size_t at = 0; at + 4 <= header.size();) {
    const std::uint32_t field_len = std::uint32_t(littleEndian(&header[at], 4));
    at += 4;
    if (field_len > header.size() - at) break;
    const std::string field = header.substr(at, field_len);
    at += field_len;
    const std::string name = "index_pos=";
    if (field.size() != name.size() + 8 || field.compare(0, name.size(), name) != 0) continue;
    const std::uint64_t index_pos = littleEndian(&field[name.size()], 8);
    if (index_pos == 0) return "it has no index (a recording that was not closed: index position 0)";
    if (index_pos >= size)
      return "it is cut short: its index should start at byte " + std::to_string(index_pos) + " but the file has " +
             std::to_string(size) + " bytes";
    return "";
  }
  return "";
}

std::string rosbagReindexCommand(const std::string& path) {
  std::string quoted = "'";
  for (char c : path) quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return "rosbag reindex " + quoted + "'";
}

void openBagForReading(rosbag::Bag& bag, const std::string& path) {
  requireRegularFile(path, kNoSizeLimit, "bag");
  try {
    bag.open(path, rosbag::bagmode::Read);
  } catch (const std::exception& e) {
    const std::string why = bagIndexProblem(path);
    if (why.empty()) throw std::runtime_error("cannot open bag " + path + ": " + e.what());
    throw std::runtime_error("cannot read bag " + path + ": " + why +
                             ". Recover its complete chunks with `" + rosbagReindexCommand(path) +
                             "` (rosbag keeps the original beside it as <name>.orig.<ext>), then run again");
  }
}

std::optional<BagImage> BagImage::of(const rosbag::MessageInstance& m) {
  if (auto img = m.instantiate<sensor_msgs::Image>()) return BagImage{img, nullptr};
  if (auto img = m.instantiate<sensor_msgs::CompressedImage>()) return BagImage{nullptr, img};
  return std::nullopt;
}

cv::Mat BagImage::sweepImage(const std::string& source) const {
  return raw ? toCvImageShare(raw, ImageTarget::kSweep, source) : toGrey(*compressed, source);
}

cv::Mat BagImage::greyImage(const std::string& source) const {
  return raw ? toCvImageShare(raw, ImageTarget::kGrey8, source) : toGrey(*compressed, source);
}

std::vector<std::string> imageTopicsInBag(rosbag::Bag& bag, std::vector<std::string> topics) {
  std::set<std::string> in_bag;
  for (const rosbag::ConnectionInfo* c : rosbag::View(bag).getConnections()) in_bag.insert(c->topic);
  for (std::string& t : topics)
    if (!in_bag.count(t) && in_bag.count(t + "/compressed")) t += "/compressed";
  return topics;
}

}  // namespace fisheye_mapping
