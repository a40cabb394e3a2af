// The save folder (confineSavePath) and the verified writer (SafeFileWriter),
// without ROS: what is refused, what is written, and that nothing outside the
// folder, behind a link or at a failed save changes.
#include <fcntl.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>

#include <gtest/gtest.h>

#include "fisheye_mapping/core/common/safe_write.h"

namespace fisheye_mapping {
namespace {

namespace fs = std::filesystem;

std::string readBytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::ostringstream s;
  s << f.rdbuf();
  return s.str();
}

void writeBytes(const std::string& path, const std::string& bytes) { std::ofstream(path, std::ios::binary) << bytes; }

// Files in `dir` (names), to see that no temporary is left.
std::string listing(const std::string& dir) {
  std::string names;
  for (const auto& e : fs::directory_iterator(dir)) names += e.path().filename().string() + " ";
  return names;
}

class SafeWrite : public ::testing::Test {
 protected:
  void SetUp() override {
    char tmpl[] = "/tmp/fm_safe_write_XXXXXX";
    base_ = fs::canonical(mkdtemp(tmpl)).string();
    folder_.directory = base_ + "/saves";
    outside_ = base_ + "/outside";
    fs::create_directories(outside_);
  }
  void TearDown() override { fs::remove_all(base_); }

  std::string refusal(const std::string& requested, const SaveFolder& f) {
    try {
      confineSavePath(requested, f);
    } catch (const std::invalid_argument& e) {
      return e.what();
    }
    return "";
  }
  std::string writeError(const std::string& path, const std::string& bytes) {
    try {
      writeFileSafely(path, bytes);
    } catch (const std::runtime_error& e) {
      return e.what();
    }
    return "";
  }

  std::string base_, outside_;
  SaveFolder folder_;
};

TEST_F(SafeWrite, RelativePathsGoInsideTheFolderWhichIsCreated) {
  EXPECT_FALSE(fs::exists(folder_.directory));
  EXPECT_EQ(confineSavePath("mesh.ply", folder_), folder_.directory + "/mesh.ply");
  EXPECT_TRUE(fs::is_directory(folder_.directory));
  // A subfolder inside it is made too; "." and an inner ".." are folded.
  EXPECT_EQ(confineSavePath("run1/./x/../map.fmtsdf", folder_), folder_.directory + "/run1/map.fmtsdf");
  EXPECT_TRUE(fs::is_directory(folder_.directory + "/run1"));
  // An absolute path inside the folder is fine.
  EXPECT_EQ(confineSavePath(folder_.directory + "/a.pcd", folder_), folder_.directory + "/a.pcd");
}

TEST_F(SafeWrite, PathsOutsideTheFolderAreRefusedNamingIt) {
  const std::string e = refusal(outside_ + "/x.ply", folder_);
  EXPECT_NE(e.find("'" + outside_ + "/x.ply'"), std::string::npos) << e;
  EXPECT_NE(e.find("outside the save folder " + folder_.directory), std::string::npos) << e;
  EXPECT_NE(e.find("allow_any_save_path"), std::string::npos) << e;
  EXPECT_NE(refusal("/etc/passwd", folder_).find("outside the save folder"), std::string::npos);
  // ".." out of the folder, however spelled.
  EXPECT_NE(refusal("../outside/x.ply", folder_).find("outside the save folder"), std::string::npos);
  EXPECT_NE(refusal("a/../../x.ply", folder_).find("outside the save folder"), std::string::npos);
  EXPECT_NE(refusal(folder_.directory + "/../x.ply", folder_).find("outside the save folder"), std::string::npos);
  // A name that only starts like the folder is not inside it.
  EXPECT_NE(refusal(folder_.directory + "2/x.ply", folder_).find("outside the save folder"), std::string::npos);
  EXPECT_FALSE(fs::exists(folder_.directory + "2"));
  EXPECT_EQ(listing(outside_), "");
}

TEST_F(SafeWrite, ALinkedFolderInsideThatPointsOutIsRefused) {
  fs::create_directories(folder_.directory);
  fs::create_directory_symlink(outside_, folder_.directory + "/escape");
  const std::string e = refusal("escape/x.ply", folder_);
  EXPECT_NE(e.find("outside the save folder"), std::string::npos) << e;
  EXPECT_NE(e.find(outside_ + "/x.ply"), std::string::npos) << e;  // where it really leads
}

TEST_F(SafeWrite, AllowAnyPathWritesAnywhereButKeepsRelativePathsInside) {
  folder_.allow_any_path = true;
  EXPECT_EQ(confineSavePath(outside_ + "/x.ply", folder_), outside_ + "/x.ply");
  EXPECT_EQ(confineSavePath("../outside/y.ply", folder_), outside_ + "/y.ply");
  EXPECT_EQ(confineSavePath("z.ply", folder_), folder_.directory + "/z.ply");
  EXPECT_NE(refusal("", folder_).find("empty"), std::string::npos);
}

TEST_F(SafeWrite, EmptyPathsAndDirectoriesAreRefused) {
  EXPECT_NE(refusal("", folder_).find("empty"), std::string::npos);
  fs::create_directories(folder_.directory + "/maps");
  EXPECT_NE(refusal("maps", folder_).find("directory"), std::string::npos);
  EXPECT_NE(refusal("new/", folder_).find("directory"), std::string::npos);
  SaveFolder none;
  EXPECT_NE(refusal("x.ply", none).find("no save folder"), std::string::npos);
}

TEST_F(SafeWrite, WritesTheBytesAndReplacesAnOldFile) {
  const std::string p = outside_ + "/f.bin";
  writeFileSafely(p, std::string("first\0bytes", 11));
  EXPECT_EQ(readBytes(p), std::string("first\0bytes", 11));
  writeFileSafely(p, "second");
  EXPECT_EQ(readBytes(p), "second");
  EXPECT_EQ(listing(outside_), "f.bin ");
  // keep_previous: the old one as .1.
  writeFileSafely(p, "third", true);
  EXPECT_EQ(readBytes(p), "third");
  EXPECT_EQ(readBytes(p + ".1"), "second");
}

TEST_F(SafeWrite, ALinkAtTheTargetIsReplacedItsTargetUntouched) {
  const std::string victim = outside_ + "/victim.txt";
  writeBytes(victim, "precious");
  const std::string link = outside_ + "/link.ply";
  fs::create_symlink(victim, link);
  writeFileSafely(link, "mesh");
  EXPECT_EQ(readBytes(victim), "precious");
  EXPECT_FALSE(fs::is_symlink(link));
  EXPECT_EQ(readBytes(link), "mesh");
  // A dangling link is replaced too, and nothing appears where it pointed.
  fs::create_symlink(outside_ + "/nowhere.txt", outside_ + "/dangling.ply");
  writeFileSafely(outside_ + "/dangling.ply", "x");
  EXPECT_FALSE(fs::exists(outside_ + "/nowhere.txt"));
}

TEST_F(SafeWrite, FifosDevicesAndDirectoriesAreRefusedUntouched) {
  const std::string fifo = outside_ + "/pipe.ply";
  ASSERT_EQ(mkfifo(fifo.c_str(), 0644), 0);
  std::string e = writeError(fifo, "x");  // must not block
  EXPECT_NE(e.find(fifo + ": is a FIFO, not a regular file"), std::string::npos) << e;
  EXPECT_TRUE(fs::is_fifo(fifo));
  e = writeError("/dev/null", "x");
  EXPECT_NE(e.find("/dev/null: is a character device"), std::string::npos) << e;
  EXPECT_TRUE(fs::is_character_file("/dev/null"));
  e = writeError("/dev/full", "x");
  EXPECT_NE(e.find("character device"), std::string::npos) << e;
  fs::create_directory(outside_ + "/d");
  EXPECT_NE(writeError(outside_ + "/d", "x").find("is a directory"), std::string::npos);
  EXPECT_NE(writeError(outside_ + "/no/such/f", "x").find("no such folder"), std::string::npos);
  EXPECT_EQ(listing(outside_ + "/d"), "");
  EXPECT_EQ(unsafeTargetKind(outside_ + "/missing"), "");
}

TEST_F(SafeWrite, AFullDeviceIsAnErrorWithTheOsMessage) {
  // The checked write on its own (a save never opens a device itself).
  const int fd = ::open("/dev/full", O_WRONLY | O_CLOEXEC);
  ASSERT_GE(fd, 0);
  const std::string data(1 << 16, 'x');
  try {
    writeAllTo(fd, data.data(), data.size(), "/dev/full");
    ADD_FAILURE() << "a write to /dev/full succeeded";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("/dev/full: write failed: No space left on device"), std::string::npos)
        << e.what();
  }
  ::close(fd);
}

// A file-size limit (RLIMIT_FSIZE) makes writes fail as a full disk does:
// the save throws with the OS error, the old file stays, no temporary is left.
TEST_F(SafeWrite, AWriteThatFailsPartWayKeepsTheOldFile) {
  const std::string p = outside_ + "/map.bin";
  writeBytes(p, "old contents");
  struct rlimit old {};
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &old), 0);
  struct sigaction ignore {}, previous {};
  ignore.sa_handler = SIG_IGN;
  sigaction(SIGXFSZ, &ignore, &previous);
  struct rlimit small = old;
  small.rlim_cur = 4096;
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &small), 0);
  const std::string e = writeError(p, std::string(100000, 'n'));
  setrlimit(RLIMIT_FSIZE, &old);
  sigaction(SIGXFSZ, &previous, nullptr);
  EXPECT_NE(e.find(p + ": write failed: File too large"), std::string::npos) << e;
  EXPECT_EQ(readBytes(p), "old contents");
  EXPECT_EQ(listing(outside_), "map.bin ");
}

TEST_F(SafeWrite, AnUncommittedWriterLeavesNothing) {
  const std::string p = outside_ + "/half.bin";
  {
    SafeFileWriter w(p);
    w.write("abc", 3);
    EXPECT_TRUE(fs::exists(w.tempPath()));
    EXPECT_EQ(fs::path(w.tempPath()).parent_path(), fs::path(outside_));
  }
  EXPECT_EQ(listing(outside_), "");
}

TEST_F(SafeWrite, WriteAtPatchesBytesAlreadyWritten) {
  const std::string p = outside_ + "/h.bin";
  SafeFileWriter w(p);
  w.write("....body", 8);
  w.writeAt("HEAD", 4, 0);
  EXPECT_THROW(w.writeAt("x", 1, 8), std::runtime_error);
  w.commit();
  EXPECT_EQ(readBytes(p), "HEADbody");
  EXPECT_THROW(w.write("x", 1), std::runtime_error);
}

TEST(CaptureFileOutput, ReturnsWhatTheWriterWroteByName) {
  const std::string bytes = captureFileOutput([](const std::string& name) {
    std::ofstream f(name, std::ios::binary);
    f << "ply\n" << std::string("\0\1\2", 3);
  });
  EXPECT_EQ(bytes, std::string("ply\n\0\1\2", 7));
}

}  // namespace
}  // namespace fisheye_mapping
