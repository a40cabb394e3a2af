// The map file's policy (MapSession, the TSDF nodelet's save_map_on_shutdown,
// reload_map_on_start and autosave_period) without ROS: checked against the
// files on disk (their bytes and block counts) after each step.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "fisheye_mapping/core/sim/analytic_scene.h"
#include "fisheye_mapping/core/tsdf/map_session.h"
#include "fisheye_mapping/core/tsdf/tsdf_map.h"
#include "test_utils.h"

namespace fisheye_mapping {
namespace {

namespace fs = std::filesystem;

TsdfConfig smallMap() {
  TsdfConfig cfg;
  cfg.voxel_size = 0.1;
  cfg.local_map_size = Eigen::Vector3d(20, 20, 3);
  return cfg;
}

// Fuses `frames` views of a wall 6 m ahead: a non-empty map.
void fuseWall(TsdfMap* map, int frames) {
  const CameraModel cam = CameraModel::unified(test::makeIntrinsics(130, 130, 127.5, 67.5, 256, 136), 0.98, 0, 0, 0, 0);
  analytic::Scene s;
  s.boxes.push_back({Eigen::Vector3d(6, -10, 0), Eigen::Vector3d(7, 10, 4)});
  for (int i = 0; i < frames; ++i) {
    const Eigen::Isometry3d T = analytic::lookAt(Eigen::Vector3d(0.1 * i, 0, 1.5), Eigen::Vector3d(10, 0, 1));
    map->integrate(s.render(cam, T), cam, T, T.translation());
  }
}

std::string bytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

struct Log {
  std::vector<std::string> info, errors;
  MapSession::Log fn() {
    return [this](bool error, const std::string& m) { (error ? errors : info).push_back(m); };
  }
  bool saidInfo(const std::string& part) const {
    for (const auto& m : info)
      if (m.find(part) != std::string::npos) return true;
    return false;
  }
};

class MapSessionTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = ::testing::TempDir() + "/test_map_session_" + ::testing::UnitTest::GetInstance()->current_test_info()->name();
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    path_ = dir_ + "/map.fmtsdf";
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string dir_, path_;
};

TEST_F(MapSessionTest, WithoutAPathNothingIsWritten) {
  Log log;
  MapSession session("", log.fn());
  TsdfMap map(smallMap());
  fuseWall(&map, 2);
  session.changed();
  EXPECT_FALSE(session.enabled());
  EXPECT_FALSE(session.start(map, true));
  EXPECT_FALSE(session.save(map, "x"));
  EXPECT_FALSE(session.autosave(map));
  session.shutdown(map);
  EXPECT_TRUE(fs::is_empty(dir_));
  EXPECT_TRUE(log.info.empty() && log.errors.empty());
}

TEST_F(MapSessionTest, ShutdownSavesAChangedMapAndAnUnchangedOneIsNotRewritten) {
  Log log;
  TsdfMap map(smallMap());
  {
    MapSession session(path_, log.fn());
    EXPECT_FALSE(session.start(map, false));
    fuseWall(&map, 3);
    session.changed();
    EXPECT_FALSE(session.unchanged());
    session.shutdown(map);
    EXPECT_EQ(session.savesOk(), 1u);
  }
  ASSERT_TRUE(fs::is_regular_file(path_));
  EXPECT_EQ(TsdfMap::readHeader(path_).num_blocks, map.numBlocks());
  EXPECT_FALSE(fs::exists(path_ + ".1"));  // nothing was there to keep
  // A new run resumes from it; unchanged, it is not written again.
  const auto mtime = fs::last_write_time(path_);
  TsdfMap resumed(smallMap());
  MapSession again(path_, log.fn());
  EXPECT_TRUE(again.start(resumed, true));
  EXPECT_EQ(resumed.numBlocks(), map.numBlocks());
  EXPECT_TRUE(again.unchanged());
  again.shutdown(resumed);
  EXPECT_EQ(again.savesOk(), 0u);
  EXPECT_EQ(fs::last_write_time(path_), mtime);
  EXPECT_TRUE(log.saidInfo("not rewritten"));
}

TEST_F(MapSessionTest, TheFirstSaveKeepsTheFileFoundThereAndAnEmptyMapNeverReplacesIt) {
  Log log;
  TsdfMap old_map(smallMap());
  fuseWall(&old_map, 2);
  old_map.save(path_);
  const std::string old_bytes = bytes(path_);
  const size_t old_blocks = old_map.numBlocks();
  // A respawn: the new run starts empty (no reload) and is told what is there.
  TsdfMap map(smallMap());
  MapSession session(path_, log.fn());
  EXPECT_FALSE(session.start(map, false));
  EXPECT_TRUE(log.saidInfo("holds a map of " + std::to_string(old_blocks) + " blocks"));
  session.changed();
  EXPECT_FALSE(session.autosave(map));  // empty: never worth a file
  EXPECT_FALSE(session.save(map, "shutdown"));  // refused: empty over non-empty
  EXPECT_EQ(session.savesFailed(), 1u);
  EXPECT_FALSE(session.lastError().empty());
  EXPECT_EQ(bytes(path_), old_bytes);
  // A real map: the first save keeps the old file as .1, the second does not touch .1.
  fuseWall(&map, 4);
  session.changed();
  EXPECT_TRUE(session.autosave(map));
  EXPECT_EQ(bytes(path_ + ".1"), old_bytes);
  EXPECT_EQ(TsdfMap::readHeader(path_).num_blocks, map.numBlocks());
  fuseWall(&map, 1);
  session.changed();
  EXPECT_TRUE(session.save(map, "shutdown"));
  EXPECT_EQ(bytes(path_ + ".1"), old_bytes);
  EXPECT_EQ(session.savesOk(), 2u);
  EXPECT_FALSE(session.autosave(map));  // unchanged since
}

TEST_F(MapSessionTest, ABadMainFileResumesFromTheBackupWhichTheNextSaveLeavesAlone) {
  Log log;
  TsdfMap good(smallMap());
  fuseWall(&good, 3);
  good.save(path_ + ".1");
  const std::string backup = bytes(path_ + ".1");
  std::ofstream(path_, std::ios::binary) << "not a map";
  TsdfMap map(smallMap());
  MapSession session(path_, log.fn());
  EXPECT_TRUE(session.start(map, true));
  EXPECT_EQ(map.numBlocks(), good.numBlocks());
  ASSERT_EQ(log.errors.size(), 1u);
  EXPECT_NE(log.errors[0].find("cannot resume from " + path_ + ":"), std::string::npos) << log.errors[0];
  EXPECT_FALSE(session.unchanged());  // loaded from .1, not from the file it saves to
  session.shutdown(map);
  EXPECT_EQ(TsdfMap::readHeader(path_).num_blocks, good.numBlocks());
  EXPECT_EQ(bytes(path_ + ".1"), backup);
}

TEST_F(MapSessionTest, NoLoadableFileStartsEmptyAndSaysSo) {
  Log log;
  TsdfMap map(smallMap());
  MapSession session(path_, log.fn());
  EXPECT_FALSE(session.start(map, true));
  EXPECT_EQ(map.numBlocks(), 0u);
  EXPECT_TRUE(log.saidInfo("no loadable map at " + path_));
}

TEST_F(MapSessionTest, AFailedSaveIsCountedAndNamed) {
  Log log;
  TsdfMap map(smallMap());
  fuseWall(&map, 2);
  MapSession session(dir_ + "/no/such/folder/map.fmtsdf", log.fn());
  session.changed();
  EXPECT_FALSE(session.save(map, "autosave"));
  EXPECT_EQ(session.savesFailed(), 1u);
  ASSERT_EQ(log.errors.size(), 1u);
  EXPECT_EQ(log.errors[0].rfind("autosave: map not saved: ", 0), 0u) << log.errors[0];
}

}  // namespace
}  // namespace fisheye_mapping
