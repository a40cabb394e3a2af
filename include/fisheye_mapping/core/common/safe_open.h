// Reading the files users name (calibration, detector models, maps, images):
// one helper that opens them without blocking and refuses what is not a
// regular file (a FIFO would block the reader forever, a device would stream
// without end) or is larger than that kind of file can be. No ROS.
#ifndef FISHEYE_MAPPING_CORE_COMMON_SAFE_OPEN_H_
#define FISHEYE_MAPPING_CORE_COMMON_SAFE_OPEN_H_

#include <cstdint>
#include <string>

#include <opencv2/core.hpp>

namespace fisheye_mapping {

// Size bounds of the files read (bytes).
constexpr std::uint64_t kMaxCalibrationFileBytes = 1u << 20;         ///< camchain, mount, stage YAML: 1 MiB
constexpr std::uint64_t kMaxImageFileBytes = std::uint64_t(1) << 30;  ///< one image: 1 GiB
constexpr std::uint64_t kMaxModelFileBytes = std::uint64_t(4) << 30;  ///< a detector's weights: 4 GiB
constexpr std::uint64_t kMaxMapFileBytes = std::uint64_t(1) << 40;    ///< a TSDF map: 1 TiB
constexpr std::uint64_t kNoSizeLimit = ~std::uint64_t(0);

/// What is wrong with reading `path` as a regular file of at most `max_bytes`
/// ("" when nothing): it is opened read-only with O_NONBLOCK (a FIFO without
/// a writer or a device does not block) and fstat'ed, e.g. "is a FIFO (named
/// pipe), not a regular file", "is a directory", "cannot open (No such file or
/// directory)", "is 2000000 bytes, more than 1048576". `size` gets its size.
std::string regularFileProblem(const std::string& path, std::uint64_t max_bytes, std::uint64_t* size = nullptr);

/// Throws std::runtime_error "<what> <path>: <problem>" unless regularFileProblem()
/// is empty; returns the file's size.
std::uint64_t requireRegularFile(const std::string& path, std::uint64_t max_bytes, const std::string& what);

/// The whole content of a regular file of at most `max_bytes` (read through
/// the descriptor that was checked: a file swapped for a FIFO in between is
/// not read). Throws std::runtime_error "<what> <path>: <problem>".
std::string readRegularFile(const std::string& path, std::uint64_t max_bytes, const std::string& what);

/// An encoded image (PNG, JPEG, TIFF, ...: what cv::imdecode reads) decoded
/// with `flags`; "" or what is wrong: no data, cv::imdecode cannot decode it,
/// or a JPEG cut short (no end-of-image marker: libjpeg only warns and fills
/// the rest with grey).
std::string decodeImage(const unsigned char* data, std::size_t size, int flags, cv::Mat* out);

/// The image file `path` decoded with `flags` (cv::IMREAD_*): a regular file
/// of at most kMaxImageFileBytes that decodes completely; throws
/// std::runtime_error "<what> <path>: <problem>".
cv::Mat readImageFile(const std::string& path, int flags, const std::string& what);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_COMMON_SAFE_OPEN_H_
