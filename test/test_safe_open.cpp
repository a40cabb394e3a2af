// common/safe_open.h: files users name are opened without blocking and must be
// regular files of bounded size; images must decode completely (a JPEG cut
// short is an error, not grey pixels).
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "fisheye_mapping/core/common/safe_open.h"

using namespace fisheye_mapping;

namespace {
const std::string kDir = "/tmp/fm_test_safe_open_" + std::to_string(getpid());

std::string errorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "no error";
}

std::string write(const std::string& name, const std::string& bytes) {
  const std::string p = kDir + "/" + name;
  std::ofstream(p, std::ios::binary) << bytes;
  return p;
}

// A 64x48 grey gradient, encoded.
std::vector<uchar> encoded(const std::string& ext) {
  cv::Mat img(48, 64, CV_8UC1);
  for (int y = 0; y < img.rows; ++y)
    for (int x = 0; x < img.cols; ++x) img.at<uchar>(y, x) = uchar((x * 4 + y * 2) & 0xFF);
  std::vector<uchar> buf;
  EXPECT_TRUE(cv::imencode(ext, img, buf));
  return buf;
}
}  // namespace

class SafeOpen : public ::testing::Test {
 protected:
  void SetUp() override { ::mkdir(kDir.c_str(), 0700); }
  void TearDown() override { std::system(("rm -rf " + kDir).c_str()); }
};

TEST_F(SafeOpen, FifoIsRefusedAtOnceWithoutBlocking) {
  const std::string fifo = kDir + "/fifo";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_EQ(regularFileProblem(fifo, kNoSizeLimit), "is a FIFO (named pipe), not a regular file");
  EXPECT_EQ(errorOf([&] { readRegularFile(fifo, kMaxCalibrationFileBytes, "camchain"); }),
            "camchain " + fifo + ": is a FIFO (named pipe), not a regular file");
  EXPECT_EQ(errorOf([&] { readImageFile(fifo, cv::IMREAD_GRAYSCALE, "image"); }),
            "image " + fifo + ": is a FIFO (named pipe), not a regular file");
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 2.0);
}

TEST_F(SafeOpen, DevicesDirectoriesMissingAndOversizedFilesAreRefused) {
  EXPECT_EQ(regularFileProblem("/dev/zero", kNoSizeLimit), "is a character device, not a regular file");
  EXPECT_EQ(regularFileProblem(kDir, kNoSizeLimit), "is a directory, not a regular file");
  EXPECT_EQ(regularFileProblem(kDir + "/none", kNoSizeLimit), "cannot open (No such file or directory)");
  EXPECT_EQ(regularFileProblem("", kNoSizeLimit), "no file name given");
  const std::string f = write("ten.bin", "0123456789");
  std::uint64_t size = 0;
  EXPECT_EQ(regularFileProblem(f, 10, &size), "");
  EXPECT_EQ(size, 10u);
  EXPECT_EQ(regularFileProblem(f, 9), "is 10 bytes, more than the 9 allowed");
  EXPECT_EQ(errorOf([&] { requireRegularFile(f, 9, "model"); }), "model " + f + ": is 10 bytes, more than the 9 allowed");
  EXPECT_EQ(readRegularFile(f, 10, "x"), "0123456789");
}

TEST_F(SafeOpen, ImagesMustDecodeCompletely) {
  for (const std::string ext : {".png", ".jpg"}) {
    const std::vector<uchar> whole = encoded(ext);
    cv::Mat img;
    EXPECT_EQ(decodeImage(whole.data(), whole.size(), cv::IMREAD_GRAYSCALE, &img), "") << ext;
    EXPECT_EQ(img.size(), cv::Size(64, 48)) << ext;
    const std::string path = write("whole" + ext, std::string(whole.begin(), whole.end()));
    EXPECT_EQ(readImageFile(path, cv::IMREAD_GRAYSCALE, "image").size(), cv::Size(64, 48)) << ext;
    // Cut to 60 %: an error naming what is wrong, never an image.
    const std::size_t cut = whole.size() * 6 / 10;
    cv::Mat none;
    const std::string why = decodeImage(whole.data(), cut, cv::IMREAD_GRAYSCALE, &none);
    EXPECT_TRUE(none.empty()) << ext;
    if (ext == ".jpg") EXPECT_EQ(why, "JPEG cut short (" + std::to_string(cut) + " bytes, no end-of-image marker)");
    else EXPECT_NE(why.find("cannot decode"), std::string::npos) << why;
    const std::string cut_path = write("cut" + ext, std::string(whole.begin(), whole.begin() + long(cut)));
    EXPECT_EQ(errorOf([&] { readImageFile(cut_path, cv::IMREAD_GRAYSCALE, "--image cam0:"); }),
              "--image cam0: " + cut_path + ": " + why);
  }
  cv::Mat img;
  EXPECT_EQ(decodeImage(nullptr, 0, cv::IMREAD_GRAYSCALE, &img), "no data");
  const std::string junk = "not an image at all";
  EXPECT_NE(decodeImage(reinterpret_cast<const uchar*>(junk.data()), junk.size(), cv::IMREAD_GRAYSCALE, &img).find(
                "cannot decode"),
            std::string::npos);
}
