#include "fisheye_mapping/core/common/safe_open.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <stdexcept>

#include <opencv2/imgcodecs.hpp>

namespace fisheye_mapping {
namespace {

// A descriptor closed on every path out.
struct Fd {
  int fd = -1;
  ~Fd() {
    if (fd >= 0) ::close(fd);
  }
};

std::string kindOf(mode_t mode) {
  if (S_ISDIR(mode)) return "is a directory";
  if (S_ISFIFO(mode)) return "is a FIFO (named pipe)";
  if (S_ISCHR(mode)) return "is a character device";
  if (S_ISBLK(mode)) return "is a block device";
  if (S_ISSOCK(mode)) return "is a socket";
  return "is a special file";
}

// Opens and checks; fd.fd stays open for reading on success.
std::string openChecked(const std::string& path, std::uint64_t max_bytes, Fd& fd, std::uint64_t* size) {
  if (path.empty()) return "no file name given";
  fd.fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY);
  if (fd.fd < 0) return std::string("cannot open (") + std::strerror(errno) + ")";
  struct stat st {};
  if (::fstat(fd.fd, &st) != 0) return std::string("cannot stat (") + std::strerror(errno) + ")";
  if (!S_ISREG(st.st_mode)) return kindOf(st.st_mode) + ", not a regular file";
  const auto bytes = static_cast<std::uint64_t>(st.st_size);
  if (size) *size = bytes;
  if (bytes > max_bytes)
    return "is " + std::to_string(bytes) + " bytes, more than the " + std::to_string(max_bytes) + " allowed";
  return "";
}

[[noreturn]] void fail(const std::string& what, const std::string& path, const std::string& why) {
  throw std::runtime_error((what.empty() ? "" : what + " ") + path + ": " + why);
}

}  // namespace

std::string regularFileProblem(const std::string& path, std::uint64_t max_bytes, std::uint64_t* size) {
  Fd fd;
  return openChecked(path, max_bytes, fd, size);
}

std::uint64_t requireRegularFile(const std::string& path, std::uint64_t max_bytes, const std::string& what) {
  std::uint64_t size = 0;
  const std::string why = regularFileProblem(path, max_bytes, &size);
  if (!why.empty()) fail(what, path, why);
  return size;
}

std::string readRegularFile(const std::string& path, std::uint64_t max_bytes, const std::string& what) {
  Fd fd;
  std::uint64_t size = 0;
  const std::string why = openChecked(path, max_bytes, fd, &size);
  if (!why.empty()) fail(what, path, why);
  std::string data;
  data.resize(static_cast<std::size_t>(size));
  std::size_t got = 0;
  while (got < data.size()) {
    const ssize_t n = ::read(fd.fd, &data[got], data.size() - got);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) fail(what, path, std::string("cannot read (") + std::strerror(errno) + ")");
    if (n == 0) break;  // shrank while read
    got += static_cast<std::size_t>(n);
  }
  data.resize(got);
  return data;
}

std::string decodeImage(const unsigned char* data, std::size_t size, int flags, cv::Mat* out) {
  if (size == 0) return "no data";
  if (size > kMaxImageFileBytes) return std::to_string(size) + " bytes, more than an image may have";
  // A JPEG ends with its end-of-image marker FF D9 (padding zeros aside); one
  // cut short lacks it, and libjpeg decodes it with a warning only.
  if (size >= 2 && data[0] == 0xFF && data[1] == 0xD8) {
    std::size_t end = size;
    while (end > 2 && data[end - 1] == 0) --end;
    if (end < 4 || data[end - 2] != 0xFF || data[end - 1] != 0xD9)
      return "JPEG cut short (" + std::to_string(size) + " bytes, no end-of-image marker)";
  }
  const cv::Mat buf(1, int(std::min<std::size_t>(size, std::size_t(INT32_MAX))), CV_8UC1, const_cast<unsigned char*>(data));
  cv::Mat img;
  try {
    img = cv::imdecode(buf, flags);
  } catch (const cv::Exception& e) {
    return std::string("cv::imdecode failed: ") + e.what();
  }
  if (img.empty()) return "cv::imdecode cannot decode its " + std::to_string(size) + " bytes (damaged or cut short?)";
  *out = img;
  return "";
}

cv::Mat readImageFile(const std::string& path, int flags, const std::string& what) {
  const std::string bytes = readRegularFile(path, kMaxImageFileBytes, what);
  cv::Mat img;
  const std::string why = decodeImage(reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size(), flags, &img);
  if (!why.empty()) fail(what, path, why);
  return img;
}

}  // namespace fisheye_mapping
