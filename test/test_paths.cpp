// resolveOutputPath: what a user-given output path means, against
// hand-written expectations.
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>

#include <gtest/gtest.h>

#include "fisheye_mapping/core/common/paths.h"

namespace fisheye_mapping {
namespace {

namespace fs = std::filesystem;

// The invalid_argument's message, or "" when nothing was thrown.
std::string errorOf(const std::string& path, const std::string& base) {
  try {
    resolveOutputPath(path, base);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

// Sets $HOME for the test's scope.
struct HomeAs {
  explicit HomeAs(const char* value) {
    if (const char* h = std::getenv("HOME")) saved = h, had = true;
    if (value) setenv("HOME", value, 1);
    else unsetenv("HOME");
  }
  ~HomeAs() {
    if (had) setenv("HOME", saved.c_str(), 1);
    else unsetenv("HOME");
  }
  std::string saved;
  bool had = false;
};

TEST(ResolveOutputPath, RelativePathsAreTakenAgainstTheBase) {
  EXPECT_EQ(resolveOutputPath("mesh.ply", "/home/car/.ros"), "/home/car/.ros/mesh.ply");
  EXPECT_EQ(resolveOutputPath("maps/a.fmtsdf", "/data"), "/data/maps/a.fmtsdf");
  EXPECT_EQ(resolveOutputPath("./maps/../b.fmtsdf", "/data/"), "/data/b.fmtsdf");
  EXPECT_EQ(resolveOutputPath("../up.ply", "/data/run1"), "/data/up.ply");
  // The file need not exist, nor its folder (the writer reports that).
  EXPECT_EQ(resolveOutputPath("no/such/dir/m.ply", "/nonexistent"), "/nonexistent/no/such/dir/m.ply");
}

TEST(ResolveOutputPath, AbsolutePathsIgnoreTheBaseAndAreNormalized) {
  EXPECT_EQ(resolveOutputPath("/tmp/m.ply", "/data"), "/tmp/m.ply");
  EXPECT_EQ(resolveOutputPath("/tmp//x/./../m.ply", "/data"), "/tmp/m.ply");
}

TEST(ResolveOutputPath, EmptyOrRelativeBaseIsTheCurrentDirectory) {
  const std::string cwd = fs::current_path().string();
  EXPECT_EQ(resolveOutputPath("m.ply", ""), cwd + "/m.ply");
  EXPECT_EQ(resolveOutputPath("m.ply", "sub"), cwd + "/sub/m.ply");
}

TEST(ResolveOutputPath, TildeIsTheHomeDirectory) {
  HomeAs home("/home/driver");
  EXPECT_EQ(resolveOutputPath("~/maps/a.fmtsdf", "/data"), "/home/driver/maps/a.fmtsdf");
  EXPECT_EQ(resolveOutputPath("~/../other/a.ply", "/data"), "/home/other/a.ply");
  // Only a leading "~/": elsewhere, and "~name", it is an ordinary character.
  EXPECT_EQ(resolveOutputPath("a/~/b.ply", "/data"), "/data/a/~/b.ply");
  EXPECT_EQ(resolveOutputPath("~driver/b.ply", "/data"), "/data/~driver/b.ply");
}

TEST(ResolveOutputPath, TildeWithoutHomeIsRefused) {
  HomeAs home(nullptr);
  const std::string e = errorOf("~/a.ply", "/data");
  EXPECT_NE(e.find("'~/a.ply'"), std::string::npos) << e;
  EXPECT_NE(e.find("HOME is not set"), std::string::npos) << e;
}

TEST(ResolveOutputPath, EmptyPathIsRefused) {
  const std::string e = errorOf("", "/data");
  EXPECT_NE(e.find("output path is empty"), std::string::npos) << e;
}

TEST(ResolveOutputPath, DirectoriesAreRefused) {
  char tmpl[] = "/tmp/fm_paths_test_XXXXXX";
  const std::string dir = mkdtemp(tmpl);
  fs::create_directory(dir + "/maps");
  std::ofstream(dir + "/file.ply") << "x";
  // An existing directory, by relative and absolute name.
  std::string e = errorOf("maps", dir);
  EXPECT_NE(e.find("'maps' (" + dir + "/maps) is an existing directory"), std::string::npos) << e;
  EXPECT_NE(errorOf(dir + "/maps", "/data").find("existing directory"), std::string::npos);
  // A trailing separator or "..": a directory by its name, existing or not.
  e = errorOf("new/", dir);
  EXPECT_NE(e.find("'new/' (" + dir + "/new/) names a directory"), std::string::npos) << e;
  EXPECT_NE(errorOf("maps/x/..", dir).find("names a directory"), std::string::npos);
  EXPECT_NE(errorOf("/", dir).find("names a directory"), std::string::npos);
  // An existing file is fine (it is replaced by the writer).
  EXPECT_EQ(resolveOutputPath("file.ply", dir), dir + "/file.ply");
  fs::remove_all(dir);
}

}  // namespace
}  // namespace fisheye_mapping
