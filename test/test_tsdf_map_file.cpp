// Integrity of the TSDF map's files and swap store: every kind of damaged map
// file is rejected with a message naming the fault (and the block) while the
// live map stays as it was; saves are atomic and leave nothing behind on
// failure; swap files deleted, damaged or unwritable lose at most their own
// block, never the process; map_tool reads the same files. The truths are the
// documented file layout (written and patched here byte by byte) and
// snapshots of the map taken before each fault. Versions 3 and 4 (compressed)
// are read back here with zlib by their documented layout, record by record.
#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <set>
#include <tuple>

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <zlib.h>

#include "fisheye_mapping/core/sim/analytic_scene.h"
#include "fisheye_mapping/core/tsdf/tsdf_map.h"
#include "scratch_dir.h"
#include "test_utils.h"

namespace fisheye_mapping {
namespace {

namespace fs = std::filesystem;
using analytic::lookAt;
using analytic::Scene;

// Layout of version 2 (see tsdf_io.cpp), written out independently here.
constexpr size_t kHeader = 44, kRecord = 4112, kPayload = 4108;
constexpr size_t kHeaderV1 = 36, kRecordV1 = 4108;
// Version 3: the same header; records of index (12), compressed size C (4),
// C bytes of zlib stream, CRC (4).
constexpr size_t kHeadV3 = 16;

MapSaveOptions versionTwo() {
  MapSaveOptions o;
  o.format_version = 2;
  return o;
}

CameraModel smallFisheye() {
  return CameraModel::unified(test::makeIntrinsics(130, 130, 127.5, 67.5, 256, 136), 0.98, -0.02, 0.004, 2e-4,
                              -1e-4);
}

Scene street() {
  Scene s;
  s.boxes.push_back({Eigen::Vector3d(-1e3, 6, 0), Eigen::Vector3d(1e4, 7, 8)});
  s.boxes.push_back({Eigen::Vector3d(-1e3, -7, 0), Eigen::Vector3d(1e4, -6, 8)});
  s.min_incidence_cos = 0.2;
  return s;
}

Eigen::Isometry3d carCamera(double x) { return lookAt(Eigen::Vector3d(x, 0, 1.6), Eigen::Vector3d(x + 10, 0, 0.6)); }

TsdfConfig smallLocalMap(const std::string& swap_dir = "") {
  TsdfConfig cfg;
  cfg.voxel_size = 0.1;
  cfg.local_map_size = Eigen::Vector3d(20, 20, 3);
  cfg.swap_directory = swap_dir;
  return cfg;
}

// A grey image of the camera's size with every value 0..255 (the map's
// intensity channel; what it shows does not matter here).
cv::Mat greyPattern(const CameraModel& cam) {
  cv::Mat g(cam.height(), cam.width(), CV_8UC1);
  for (int v = 0; v < g.rows; ++v)
    for (int u = 0; u < g.cols; ++u) g.at<uint8_t>(v, u) = static_cast<uint8_t>((7 * u + 3 * v) % 256);
  return g;
}

void drive(TsdfMap* map, double from, double to, double step) {
  const CameraModel cam = smallFisheye();
  const Scene s = street();
  const cv::Mat grey = greyPattern(cam);
  for (double x = from; step > 0 ? x <= to : x >= to; x += step) {
    map->integrate(s.render(cam, carCamera(x)), cam, carCamera(x), Eigen::Vector3d(x, 0, 0), {}, grey);
  }
}

using Snapshot = std::map<std::tuple<int, int, int>, VoxelBlock>;

Snapshot snapshot(const TsdfMap& map) {
  Snapshot out;
  for (const BlockIndex& b : map.allBlocks()) {
    const VoxelBlock* blk = map.block(b);
    if (blk) out[{b.x(), b.y(), b.z()}] = *blk;
  }
  return out;
}

// The map holds exactly the snapshot's blocks, bit for bit (with_grey: their
// intensities too).
::testing::AssertionResult sameAs(const TsdfMap& map, const Snapshot& snap, bool with_grey = false) {
  if (map.numBlocks() != snap.size()) {
    return ::testing::AssertionFailure() << map.numBlocks() << " blocks, expected " << snap.size();
  }
  for (const auto& kv : snap) {
    const auto& [x, y, z] = kv.first;
    const VoxelBlock* b = map.block(BlockIndex(x, y, z));
    if (!b) return ::testing::AssertionFailure() << "block " << x << " " << y << " " << z << " missing";
    if (std::memcmp(b->voxels.data(), kv.second.voxels.data(), sizeof(b->voxels)) != 0) {
      return ::testing::AssertionFailure() << "block " << x << " " << y << " " << z << " differs";
    }
    if (with_grey && b->grey != kv.second.grey) {
      return ::testing::AssertionFailure() << "block " << x << " " << y << " " << z << ": intensities differ";
    }
  }
  return ::testing::AssertionSuccess();
}

// A fresh directory inside the program's scratch directory (removed when
// the program ends).
std::string tempDir() { return fisheye_mapping::test::freshScratchSubdir("/tmp/fm_map_file_test_"); }

std::string readBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

void writeBytes(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
}

template <typename T>
void put(std::string* bytes, size_t at, T v) {
  std::memcpy(&(*bytes)[at], &v, sizeof(T));
}
template <typename T>
T get(const std::string& bytes, size_t at) {
  T v;
  std::memcpy(&v, &bytes[at], sizeof(T));
  return v;
}

void fixHeaderCrc(std::string* b) { put<uint32_t>(b, 40, crc32(b->data(), 40)); }
void fixBlockCrc(std::string* b, size_t i) {
  const size_t at = kHeader + i * kRecord;
  put<uint32_t>(b, at + kPayload, crc32(b->data() + at, kPayload));
}
size_t voxelAt(size_t block, int voxel) { return kHeader + block * kRecord + 12 + 8 * voxel; }
std::string blockName(const std::string& bytes, size_t i) {
  const size_t at = kHeader + i * kRecord;
  return "block #" + std::to_string(i) + " (" + std::to_string(get<int32_t>(bytes, at)) + ", " +
         std::to_string(get<int32_t>(bytes, at + 4)) + ", " + std::to_string(get<int32_t>(bytes, at + 8)) + ")";
}

TEST(Crc32, KnownValues) {
  EXPECT_EQ(crc32("123456789", 9), 0xCBF43926u);  // the standard check value
  EXPECT_EQ(crc32("", 0), 0u);
  EXPECT_EQ(crc32("The quick brown fox jumps over the lazy dog", 43), 0x414FA339u);
  EXPECT_EQ(crc32("6789", 4, crc32("12345", 5)), 0xCBF43926u);  // chained
}

// One map (both stores) and its file, shared by the file tests.
class MapFile : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new std::string(tempDir());
    map_ = new TsdfMap(smallLocalMap());
    drive(map_, 0, 28, 4.0);
    snap_ = new Snapshot(snapshot(*map_));
    map_->save(*dir_ + "/good.fmtsdf", versionTwo());
    good_ = new std::string(readBytes(*dir_ + "/good.fmtsdf"));
    MapSaveOptions three;
    three.format_version = 3;
    map_->save(*dir_ + "/good3.fmtsdf", three);
    good3_ = new std::string(readBytes(*dir_ + "/good3.fmtsdf"));
    map_->save(*dir_ + "/good4.fmtsdf");
    good4_ = new std::string(readBytes(*dir_ + "/good4.fmtsdf"));
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete map_;
    delete snap_;
    delete good_;
    delete good3_;
    delete good4_;
    delete dir_;
  }
  // A live map loaded from the good file: a bad file must leave it as it is.
  void SetUp() override {
    live_ = std::make_unique<TsdfMap>(smallLocalMap());
    live_->load(*dir_ + "/good.fmtsdf");
    ASSERT_TRUE(sameAs(*live_, *snap_));
  }
  // Loading `bytes` fails with a message holding each of `expected`; the live
  // map is unchanged.
  void expectRejected(const std::string& bytes, const std::vector<std::string>& expected) {
    const std::string path = *dir_ + "/bad.fmtsdf";
    writeBytes(path, bytes);
    try {
      live_->load(path);
      ADD_FAILURE() << "a damaged file was loaded";
    } catch (const std::runtime_error& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(path), std::string::npos) << msg;
      for (const auto& s : expected) EXPECT_NE(msg.find(s), std::string::npos) << "'" << s << "' not in: " << msg;
    }
    EXPECT_TRUE(sameAs(*live_, *snap_)) << "the live map changed";
  }
  size_t numBlocks() const { return snap_->size(); }

  static std::string* dir_;
  static TsdfMap* map_;
  static Snapshot* snap_;
  static std::string* good_;   // version 2
  static std::string* good3_;  // version 3
  static std::string* good4_;  // version 4 (the default)
  std::unique_ptr<TsdfMap> live_;
};
std::string* MapFile::dir_ = nullptr;
TsdfMap* MapFile::map_ = nullptr;
Snapshot* MapFile::snap_ = nullptr;
std::string* MapFile::good_ = nullptr;
std::string* MapFile::good3_ = nullptr;
std::string* MapFile::good4_ = nullptr;

TEST_F(MapFile, LayoutAndRoundTrip) {
  ASSERT_GT(map_->numSwappedBlocks(), 0u);  // both stores are saved
  ASSERT_GT(numBlocks(), 500u);
  const std::string& b = *good_;
  EXPECT_EQ(b.size(), kHeader + numBlocks() * kRecord);
  EXPECT_EQ(b.substr(0, 8), "FMTSDF01");
  EXPECT_EQ(get<uint32_t>(b, 8), 2u);
  EXPECT_EQ(get<double>(b, 12), 0.1);
  EXPECT_EQ(get<double>(b, 20), 4.0);
  EXPECT_EQ(get<uint64_t>(b, 28), numBlocks());
  EXPECT_EQ(get<float>(b, 36), 100.0f);
  EXPECT_EQ(get<uint32_t>(b, 40), crc32(b.data(), 40));
  for (size_t i = 0; i < numBlocks(); ++i) {
    ASSERT_EQ(get<uint32_t>(b, kHeader + i * kRecord + kPayload), crc32(b.data() + kHeader + i * kRecord, kPayload));
  }
  const MapFileInfo info = TsdfMap::readHeader(*dir_ + "/good.fmtsdf");
  EXPECT_EQ(info.version, 2u);
  EXPECT_EQ(info.num_blocks, numBlocks());
  EXPECT_EQ(info.file_size, b.size());
  // Saved again, the same bytes (block order aside, the same records).
  map_->save(*dir_ + "/again.fmtsdf", versionTwo());
  EXPECT_EQ(readBytes(*dir_ + "/again.fmtsdf").size(), b.size());
  TsdfMap again(smallLocalMap());
  again.load(*dir_ + "/again.fmtsdf");
  EXPECT_TRUE(sameAs(again, *snap_));
  EXPECT_FALSE(fs::exists(*dir_ + "/again.fmtsdf.tmp"));
}

TEST_F(MapFile, BlockCountZeroIsRejected) {
  std::string b = *good_;
  put<uint64_t>(&b, 28, 0);
  expectRejected(b, {"header checksum mismatch"});  // as a hostile edit leaves it
  fixHeaderCrc(&b);
  expectRejected(b, {"header counts 0 blocks"});  // even with a consistent header
}

TEST_F(MapFile, BlockCountSmallerThanTheBlocksPresentIsRejected) {
  std::string b = *good_;
  put<uint64_t>(&b, 28, 10);
  expectRejected(b, {"header checksum mismatch"});
  fixHeaderCrc(&b);
  expectRejected(b, {"header counts 10 blocks"});
  put<uint64_t>(&b, 28, numBlocks() + 1);
  fixHeaderCrc(&b);
  expectRejected(b, {"truncated map file"});
}

TEST_F(MapFile, BitFlipsInThePayloadFailTheChecksumNamingTheBlock) {
  // 5000 random bit flips after the header.
  std::string b = *good_;
  std::mt19937 rng(15);
  std::uniform_int_distribution<size_t> byte(kHeader, b.size() - 1);
  std::set<size_t> blocks;
  for (int i = 0; i < 5000; ++i) {
    const size_t at = byte(rng);
    b[at] = static_cast<char>(b[at] ^ (1 << (rng() % 8)));
    blocks.insert((at - kHeader) / kRecord);
  }
  expectRejected(b, {"checksum mismatch", blockName(b, *blocks.begin())});
  // One flipped bit in one voxel of block 7: that block is named.
  b = *good_;
  b[voxelAt(7, 300) + 2] ^= 0x10;
  expectRejected(b, {blockName(b, 7) + ": checksum mismatch"});
}

TEST_F(MapFile, NonFiniteAndOutOfRangeVoxelsAreRejected) {
  struct Case {
    const char* name;
    int field;  // 0 tsdf, 1 weight
    float value;
  };
  const Case cases[] = {{"NaN tsdf", 0, NAN},        {"inf tsdf", 0, INFINITY},  {"tsdf 1.5", 0, 1.5f},
                        {"tsdf -3", 0, -3.0f},       {"NaN weight", 1, NAN},     {"negative weight", 1, -1.0f},
                        {"inf weight", 1, INFINITY}, {"weight above the cap", 1, 250.0f}};
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    std::string b = *good_;
    put<float>(&b, voxelAt(3, 77) + 4 * c.field, c.value);
    fixBlockCrc(&b, 3);  // a consistent checksum: the values themselves are checked
    expectRejected(b, {blockName(b, 3) + ", voxel 77"});
  }
}

TEST_F(MapFile, GarbageBlockIndicesAreRejected) {
  std::string b = *good_;
  put<int32_t>(&b, kHeader + 5 * kRecord, 125000000);  // 1e8 m with 0.8 m blocks
  fixBlockCrc(&b, 5);
  expectRejected(b, {blockName(b, 5), "garbage index"});
  b = *good_;
  put<int32_t>(&b, kHeader + 5 * kRecord + 8, -2147483647 - 1);
  fixBlockCrc(&b, 5);
  expectRejected(b, {"garbage index"});
}

TEST_F(MapFile, DuplicateBlocksAreRejected) {
  std::string b = *good_;
  std::memcpy(&b[kHeader + 9 * kRecord], &b[kHeader + 2 * kRecord], kRecord);  // block 2's record again as 9
  expectRejected(b, {blockName(b, 9) + ": duplicate of block #2"});
}

TEST_F(MapFile, TruncatedAndExtendedFilesAreRejected) {
  expectRejected(good_->substr(0, good_->size() / 2), {"truncated map file"});
  expectRejected(good_->substr(0, good_->size() - 1), {"truncated map file"});
  expectRejected(good_->substr(0, 40), {"bad header"});
  expectRejected(*good_ + std::string(100, '\0'), {"bytes appended"});
  expectRejected("not a map", {"bad header"});
  std::string b = *good_;
  put<uint32_t>(&b, 8, 5);
  fixHeaderCrc(&b);
  expectRejected(b, {"unknown version 5"});
}

TEST_F(MapFile, DirectoriesAndMissingFilesAreRejected) {
  EXPECT_THROW(live_->load(*dir_), std::runtime_error);
  EXPECT_THROW(live_->load(*dir_ + "/missing.fmtsdf"), std::runtime_error);
  EXPECT_TRUE(sameAs(*live_, *snap_));
}

// A version-1 file (no checksums), written here from the snapshot.
std::string versionOneFile(const Snapshot& snap) {
  std::string b(kHeaderV1, '\0');
  std::memcpy(&b[0], "FMTSDF01", 8);
  put<uint32_t>(&b, 8, 1);
  put<double>(&b, 12, 0.1);
  put<double>(&b, 20, 4.0);
  put<uint64_t>(&b, 28, snap.size());
  for (const auto& kv : snap) {
    const auto& [x, y, z] = kv.first;
    const int32_t idx[3] = {x, y, z};
    b.append(reinterpret_cast<const char*>(idx), sizeof(idx));
    b.append(reinterpret_cast<const char*>(kv.second.voxels.data()), sizeof(kv.second.voxels));
  }
  return b;
}

TEST_F(MapFile, VersionOneFilesAreReadAndChecked) {
  const std::string v1 = versionOneFile(*snap_);
  ASSERT_EQ(v1.size(), kHeaderV1 + numBlocks() * kRecordV1);
  writeBytes(*dir_ + "/v1.fmtsdf", v1);
  TsdfMap m(smallLocalMap());
  m.load(*dir_ + "/v1.fmtsdf");
  EXPECT_TRUE(sameAs(m, *snap_));
  EXPECT_EQ(TsdfMap::readHeader(*dir_ + "/v1.fmtsdf").version, 1u);
  std::string b = v1;
  put<uint64_t>(&b, 28, 0);
  expectRejected(b, {"header counts 0 blocks"});
  put<uint64_t>(&b, 28, 10);
  expectRejected(b, {"header counts 10 blocks"});
  b = v1;
  put<float>(&b, kHeaderV1 + 4 * kRecordV1 + 12 + 8 * 5, NAN);
  expectRejected(b, {"block #4", "voxel 5"});
  b = v1;
  put<float>(&b, kHeaderV1 + 4 * kRecordV1 + 12 + 8 * 5 + 4, -2.0f);
  expectRejected(b, {"block #4", "voxel 5"});
}

// --- Version 3 -----------------------------------------------------------------

// The records of a version-3 file, each as its bytes (index to CRC).
std::vector<std::string> recordsV3(const std::string& file) {
  std::vector<std::string> out;
  for (size_t at = kHeader; at + kHeadV3 <= file.size();) {
    const size_t n = kHeadV3 + get<uint32_t>(file, at + 12) + 4;
    out.push_back(file.substr(at, n));
    at += n;
  }
  return out;
}

// A version-3 file: `header`'s first 44 bytes counting `count` blocks, then
// `records`.
std::string fileV3(const std::string& header, const std::vector<std::string>& records, uint64_t count) {
  std::string b = header.substr(0, kHeader);
  put<uint64_t>(&b, 28, count);
  fixHeaderCrc(&b);
  for (const auto& r : records) b += r;
  return b;
}
std::string fileV3(const std::string& header, const std::vector<std::string>& records) {
  return fileV3(header, records, records.size());
}

void fixRecordCrc(std::string* r) { put<uint32_t>(r, r->size() - 4, crc32(r->data(), r->size() - 4)); }

// The record's zlib stream inflated (the mask and the packed voxels).
std::string inflated(const std::string& record) {
  std::string raw(64 + 4096 + 512, '\0');
  uLongf n = raw.size();
  const int rc = uncompress(reinterpret_cast<Bytef*>(&raw[0]), &n,
                            reinterpret_cast<const Bytef*>(record.data() + kHeadV3), get<uint32_t>(record, 12));
  EXPECT_EQ(rc, Z_OK);
  raw.resize(n);
  return raw;
}

// A record holding block `like`'s index and the zlib stream of `raw`, CRC fixed.
std::string recordOf(const std::string& like, const std::string& raw) {
  std::string packed(compressBound(raw.size()), '\0');
  uLongf n = packed.size();
  EXPECT_EQ(compress(reinterpret_cast<Bytef*>(&packed[0]), &n, reinterpret_cast<const Bytef*>(raw.data()), raw.size()),
            Z_OK);
  std::string r = like.substr(0, 12);
  r.resize(kHeadV3);
  put<uint32_t>(&r, 12, static_cast<uint32_t>(n));
  r += packed.substr(0, n) + std::string(4, '\0');
  fixRecordCrc(&r);
  return r;
}

// Value s of the n float32 values stored byte-plane by byte-plane from `at`
// (byte k of value s at at + k * n + s), and the reverse.
float planeValue(const std::string& raw, size_t at, size_t n, size_t s) {
  char bytes[4];
  for (size_t k = 0; k < 4; ++k) bytes[k] = raw[at + k * n + s];
  return get<float>(std::string(bytes, 4), 0);
}
void setPlaneValue(std::string* raw, size_t at, size_t n, size_t s, float v) {
  char bytes[4];
  std::memcpy(bytes, &v, 4);
  for (size_t k = 0; k < 4; ++k) (*raw)[at + k * n + s] = bytes[k];
}

std::string nameOf(const std::string& record, size_t i) {
  return "block #" + std::to_string(i) + " (" + std::to_string(get<int32_t>(record, 0)) + ", " +
         std::to_string(get<int32_t>(record, 4)) + ", " + std::to_string(get<int32_t>(record, 8)) + ")";
}

TEST_F(MapFile, VersionThreeLayoutAndRoundTrip) {
  const std::string& b = *good3_;
  EXPECT_EQ(b.substr(0, 8), "FMTSDF01");
  EXPECT_EQ(get<uint32_t>(b, 8), 3u);
  EXPECT_EQ(get<double>(b, 12), 0.1);
  EXPECT_EQ(get<double>(b, 20), 4.0);
  EXPECT_EQ(get<uint64_t>(b, 28), numBlocks());
  EXPECT_EQ(get<float>(b, 36), 100.0f);
  EXPECT_EQ(get<uint32_t>(b, 40), crc32(b.data(), 40));
  const std::vector<std::string> records = recordsV3(b);
  ASSERT_EQ(records.size(), numBlocks());
  size_t total = kHeader, stored = 0;
  for (const auto& r : records) {
    total += r.size();
    ASSERT_EQ(get<uint32_t>(r, r.size() - 4), crc32(r.data(), r.size() - 4));
    // The mask names exactly the observed voxels; tsdf values, then weights.
    const std::string raw = inflated(r);
    const VoxelBlock& truth = snap_->at({get<int32_t>(r, 0), get<int32_t>(r, 4), get<int32_t>(r, 8)});
    std::vector<int> observed;
    for (int v = 0; v < 512; ++v) {
      ASSERT_EQ((raw[v / 8] >> (v % 8)) & 1, truth.voxels[v].weight > 0 ? 1 : 0) << "voxel " << v;
      if (truth.voxels[v].weight > 0) observed.push_back(v);
      else ASSERT_EQ(truth.voxels[v].tsdf, 0.0f);  // nothing is lost by leaving it out
    }
    const size_t n = observed.size();
    ASSERT_EQ(raw.size(), 64 + 8 * n);
    for (size_t s = 0; s < n; ++s) {
      ASSERT_EQ(planeValue(raw, 64, n, s), truth.voxels[observed[s]].tsdf);
      ASSERT_EQ(planeValue(raw, 64 + 4 * n, n, s), truth.voxels[observed[s]].weight);
    }
    stored += observed.size();
  }
  EXPECT_EQ(total, b.size());
  const MapFileInfo info = TsdfMap::readHeader(*dir_ + "/good3.fmtsdf");
  EXPECT_EQ(info.version, 3u);
  EXPECT_EQ(info.num_blocks, numBlocks());
  EXPECT_EQ(info.file_size, b.size());
  TsdfMap back(smallLocalMap());
  back.load(*dir_ + "/good3.fmtsdf");
  EXPECT_TRUE(sameAs(back, *snap_));
  // Most voxels of a block lie outside the band around the surface: version 3
  // is a fraction of version 2.
  std::printf("%zu blocks, %.1f %% of their voxels observed: version 2 %zu bytes, version 3 %zu bytes (%.1f x smaller)\n",
              numBlocks(), 100.0 * stored / (512.0 * numBlocks()), good_->size(), b.size(),
              static_cast<double>(good_->size()) / b.size());
  EXPECT_LT(b.size() * 5, good_->size());
}

TEST_F(MapFile, VersionFourLayoutCarriesTheIntensities) {
  const std::string& b = *good4_;
  EXPECT_EQ(get<uint32_t>(b, 8), 4u);
  EXPECT_EQ(get<uint32_t>(b, 40), crc32(b.data(), 40));
  const std::vector<std::string> records = recordsV3(b);
  ASSERT_EQ(records.size(), numBlocks());
  size_t total = kHeader, with_grey = 0, stored = 0;
  for (const auto& r : records) {
    total += r.size();
    ASSERT_EQ(get<uint32_t>(r, r.size() - 4), crc32(r.data(), r.size() - 4));
    // Mask, tsdf plane, weight plane, then one intensity byte per stored voxel.
    const std::string raw = inflated(r);
    const VoxelBlock& truth = snap_->at({get<int32_t>(r, 0), get<int32_t>(r, 4), get<int32_t>(r, 8)});
    std::vector<int> observed;
    for (int v = 0; v < 512; ++v) {
      const bool kept = truth.voxels[v].weight > 0 || truth.grey[v] != 0;
      ASSERT_EQ((raw[v / 8] >> (v % 8)) & 1, kept ? 1 : 0) << "voxel " << v;
      if (kept) observed.push_back(v);
    }
    const size_t n = observed.size();
    ASSERT_EQ(raw.size(), 64 + 9 * n);
    for (size_t s = 0; s < n; ++s) {
      ASSERT_EQ(planeValue(raw, 64, n, s), truth.voxels[observed[s]].tsdf);
      ASSERT_EQ(planeValue(raw, 64 + 4 * n, n, s), truth.voxels[observed[s]].weight);
      ASSERT_EQ(static_cast<uint8_t>(raw[64 + 8 * n + s]), truth.grey[observed[s]]);
      with_grey += truth.grey[observed[s]] != 0;
    }
    stored += n;
  }
  EXPECT_EQ(total, b.size());
  // The drive fused images: most stored voxels near the surfaces have an intensity.
  EXPECT_GT(with_grey, stored / 10);
  TsdfMap back(smallLocalMap());
  back.load(*dir_ + "/good4.fmtsdf");
  EXPECT_TRUE(sameAs(back, *snap_, /*with_grey=*/true));
  // A version-3 file (no intensity channel) loads with every intensity 0 (none).
  TsdfMap old(smallLocalMap());
  old.load(*dir_ + "/good3.fmtsdf");
  EXPECT_TRUE(sameAs(old, *snap_));
  size_t nonzero = 0;
  for (const BlockIndex& bi : old.allBlocks()) {
    for (unsigned char g : old.block(bi)->grey) nonzero += g != 0;
  }
  EXPECT_EQ(nonzero, 0u);
  std::printf("version 3 %zu bytes, version 4 (intensities) %zu bytes (+%.1f %%)\n", good3_->size(), b.size(),
              100.0 * (static_cast<double>(b.size()) / good3_->size() - 1.0));
}

TEST_F(MapFile, VersionTwoFilesStillLoadAndCanBeWritten) {
  EXPECT_EQ(TsdfMap::readHeader(*dir_ + "/good.fmtsdf").version, 2u);
  TsdfMap m(smallLocalMap());
  m.load(*dir_ + "/good.fmtsdf");
  EXPECT_TRUE(sameAs(m, *snap_));
  // Saved again by default: version 4, the same map.
  m.save(*dir_ + "/resaved.fmtsdf");
  EXPECT_EQ(TsdfMap::readHeader(*dir_ + "/resaved.fmtsdf").version, 4u);
  TsdfMap again(smallLocalMap());
  again.load(*dir_ + "/resaved.fmtsdf");
  EXPECT_TRUE(sameAs(again, *snap_));
  // Other versions cannot be written.
  MapSaveOptions v5;
  v5.format_version = 5;
  try {
    m.save(*dir_ + "/v5.fmtsdf", v5);
    ADD_FAILURE() << "wrote format version 5";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("cannot write map format version 5"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(*dir_ + "/v5.fmtsdf"));
}

TEST_F(MapFile, VersionThreeDamageIsRejectedNamingTheBlock) {
  const std::vector<std::string> good = recordsV3(*good3_);
  ASSERT_EQ(fileV3(*good3_, good), *good3_);
  auto with = [&](size_t i, const std::string& record) {
    std::vector<std::string> r = good;
    r[i] = record;
    return fileV3(*good3_, r);
  };
  // A flipped bit in block 7's compressed voxels: its CRC, then (CRC fixed)
  // zlib's own check names it.
  std::string r7 = good[7];
  r7[kHeadV3 + r7.size() / 2] ^= 0x10;
  expectRejected(with(7, r7), {nameOf(r7, 7) + ": checksum mismatch"});
  fixRecordCrc(&r7);
  expectRejected(with(7, r7), {nameOf(r7, 7) + ": corrupt compressed voxels (format version 3)"});
  // The stream cut short (its size and CRC consistent).
  std::string cut = good[7].substr(0, good[7].size() - 7) + std::string(4, '\0');
  put<uint32_t>(&cut, 12, get<uint32_t>(good[7], 12) - 3);
  fixRecordCrc(&cut);
  expectRejected(with(7, cut), {nameOf(cut, 7) + ": corrupt compressed voxels", "incomplete deflate data"});
  // Bytes after the end of the stream.
  std::string tail = good[7].substr(0, good[7].size() - 4) + "xy" + std::string(4, '\0');
  put<uint32_t>(&tail, 12, get<uint32_t>(good[7], 12) + 2);
  fixRecordCrc(&tail);
  expectRejected(with(7, tail), {nameOf(tail, 7), "2 bytes after the end of the zlib stream"});
  // A garbage compressed size.
  std::string size = good[7];
  put<uint32_t>(&size, 12, 0xFFFFFF00u);
  expectRejected(with(7, size), {nameOf(size, 7) + ": compressed size 4294967040 bytes out of range"});
  // A mask naming one voxel more than the data hold.
  std::string raw = inflated(good[4]);
  int unset = 0;
  while ((raw[unset / 8] >> (unset % 8)) & 1) ++unset;
  raw[unset / 8] = static_cast<char>(raw[unset / 8] | (1 << (unset % 8)));
  const size_t n = (raw.size() - 64) / 8;
  expectRejected(with(4, recordOf(good[4], raw)),
                 {nameOf(good[4], 4), "inflates to " + std::to_string(raw.size()) + " bytes, its mask of " +
                                          std::to_string(n + 1) + " voxels needs " + std::to_string(64 + 8 * (n + 1))});
  // Valid streams of invalid voxels: a NaN tsdf, a weight above the cap.
  raw = inflated(good[3]);
  int first = 0;
  while (!((raw[first / 8] >> (first % 8)) & 1)) ++first;
  const size_t stored = (raw.size() - 64) / 8;
  std::string bad = raw;
  setPlaneValue(&bad, 64, stored, 0, NAN);
  expectRejected(with(3, recordOf(good[3], bad)), {nameOf(good[3], 3) + ", voxel " + std::to_string(first)});
  bad = raw;
  setPlaneValue(&bad, 64 + 4 * stored, stored, 0, 250.0f);
  expectRejected(with(3, recordOf(good[3], bad)), {nameOf(good[3], 3) + ", voxel " + std::to_string(first)});
  // Duplicates, counts and lengths.
  std::vector<std::string> dup(good.begin(), good.begin() + 10);
  dup.push_back(good[2]);
  expectRejected(fileV3(*good3_, dup), {nameOf(good[2], 10) + ": duplicate of block #2"});
  expectRejected(fileV3(*good3_, good, 0), {"header counts 0 blocks", "bytes appended"});
  expectRejected(fileV3(*good3_, good, good.size() - 1), {"bytes appended"});
  expectRejected(fileV3(*good3_, good, good.size() + 1), {"truncated map file"});
  expectRejected(fileV3(*good3_, good, good3_->size()), {"truncated map file", "room for at most"});
  expectRejected(good3_->substr(0, good3_->size() / 2), {"truncated map file"});
  expectRejected(good3_->substr(0, good3_->size() - 1), {"truncated map file"});
  expectRejected(*good3_ + std::string(100, '\0'), {"bytes appended"});
}

// Names in a directory.
std::set<std::string> listing(const std::string& dir) {
  std::set<std::string> out;
  for (const auto& e : fs::directory_iterator(dir)) out.insert(e.path().filename().string());
  return out;
}

TEST_F(MapFile, FailedSavesLeaveNothingBehind) {
  const std::string d = tempDir();
  fs::create_directory(d + "/sub");
  try {
    map_->save(d + "/sub");
    ADD_FAILURE() << "saved onto a directory";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("is a directory"), std::string::npos) << e.what();
  }
  EXPECT_EQ(listing(d), std::set<std::string>{"sub"});
  EXPECT_TRUE(fs::is_empty(d + "/sub"));
  EXPECT_THROW(map_->save(d + "/no/such/dir/map.fmtsdf"), std::runtime_error);
  EXPECT_THROW(map_->save(""), std::runtime_error);
  EXPECT_EQ(listing(d), std::set<std::string>{"sub"});

  // The disk fills up mid-save (a file size limit of 64 kB): the old map
  // stays, no .tmp is left.
  writeBytes(d + "/map.fmtsdf", *good_);
  struct rlimit old_limit;
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &old_limit), 0);
  struct rlimit small = old_limit;
  small.rlim_cur = 64 * 1024;
  signal(SIGXFSZ, SIG_IGN);  // write() then fails with EFBIG
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &small), 0);
  bool threw = false;
  std::string msg;
  try {
    map_->save(d + "/map.fmtsdf");
  } catch (const std::runtime_error& e) {
    threw = true;
    msg = e.what();
  }
  setrlimit(RLIMIT_FSIZE, &old_limit);
  signal(SIGXFSZ, SIG_DFL);
  EXPECT_TRUE(threw);
  EXPECT_NE(msg.find("write failed"), std::string::npos) << msg;
  EXPECT_EQ(listing(d), (std::set<std::string>{"map.fmtsdf", "sub"}));
  EXPECT_EQ(readBytes(d + "/map.fmtsdf"), *good_);
  fs::remove_all(d);
}

// A link at the map's path is replaced by the map, its target untouched; a
// FIFO there is refused at once and stays (issue 28).
TEST_F(MapFile, SavesNeverFollowALinkNorWriteIntoAFifo) {
  const std::string d = tempDir();
  writeBytes(d + "/victim", "precious");
  fs::create_symlink(d + "/victim", d + "/map.fmtsdf");
  map_->save(d + "/map.fmtsdf", versionTwo());
  EXPECT_EQ(readBytes(d + "/victim"), "precious");
  EXPECT_FALSE(fs::is_symlink(d + "/map.fmtsdf"));
  EXPECT_EQ(readBytes(d + "/map.fmtsdf"), *good_);
  ASSERT_EQ(mkfifo((d + "/pipe.fmtsdf").c_str(), 0644), 0);
  try {
    map_->save(d + "/pipe.fmtsdf");
    ADD_FAILURE() << "saved into a FIFO";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(d + "/pipe.fmtsdf: is a FIFO"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(fs::is_fifo(d + "/pipe.fmtsdf"));
  EXPECT_EQ(listing(d), (std::set<std::string>{"map.fmtsdf", "pipe.fmtsdf", "victim"}));
  fs::remove_all(d);
}

TEST_F(MapFile, EmptyMapNeverReplacesAMapWhenRefusedAndThePreviousIsKept) {
  const std::string d = tempDir();
  const std::string p = d + "/map.fmtsdf";
  writeBytes(p, *good_);
  MapSaveOptions safe;
  safe.refuse_empty_overwrite = true;
  safe.keep_previous = true;
  TsdfMap empty(smallLocalMap());
  try {
    empty.save(p, safe);
    ADD_FAILURE() << "an empty map replaced a non-empty one";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("refusing"), std::string::npos) << e.what();
  }
  EXPECT_EQ(readBytes(p), *good_);
  EXPECT_EQ(listing(d), std::set<std::string>{"map.fmtsdf"});
  // Nor over a file that is not a readable map (it may be a damaged good one).
  writeBytes(d + "/junk.fmtsdf", "junk");
  EXPECT_THROW(empty.save(d + "/junk.fmtsdf", safe), std::runtime_error);
  EXPECT_EQ(readBytes(d + "/junk.fmtsdf"), "junk");
  // An empty map over an empty map, or where no file is: fine.
  empty.save(d + "/empty.fmtsdf", safe);
  empty.save(d + "/empty.fmtsdf", safe);
  EXPECT_EQ(TsdfMap::readHeader(d + "/empty.fmtsdf").num_blocks, 0u);
  EXPECT_EQ(fs::file_size(d + "/empty.fmtsdf"), kHeader);
  // An explicit save (no refusal) of an empty map is the user's choice.
  empty.save(d + "/junk.fmtsdf");
  EXPECT_EQ(fs::file_size(d + "/junk.fmtsdf"), kHeader);

  // keep_previous: the old file becomes <path>.1, byte for byte.
  TsdfMap other(smallLocalMap());
  drive(&other, 0, 8, 4.0);
  other.save(p, safe);
  EXPECT_EQ(readBytes(p + ".1"), *good_);
  TsdfMap back(smallLocalMap());
  back.load(p);
  EXPECT_TRUE(sameAs(back, snapshot(other)));
  EXPECT_FALSE(fs::exists(p + ".tmp"));
  fs::remove_all(d);
}

// --- Swap store faults -------------------------------------------------------

struct SwapFault : public ::testing::Test {
  void SetUp() override {
    dir = tempDir();
    map = std::make_unique<TsdfMap>(smallLocalMap(dir + "/swap"));
    map->setSwapErrorCallback([this](bool lost, const std::string& m) {
      if (lost) messages.push_back(m);
      else ++write_failures;
    });
    drive(map.get(), 0, 40, 4.0);
    ASSERT_GT(map->numSwappedBlocks(), 100u);
  }
  void TearDown() override { fs::remove_all(dir); }
  std::vector<std::string> swapFiles() const {
    std::vector<std::string> out;
    for (const auto& e : fs::directory_iterator(dir + "/swap")) out.push_back(e.path().string());
    return out;
  }
  std::string dir;
  std::unique_ptr<TsdfMap> map;
  std::vector<std::string> messages;  // lost blocks
  size_t write_failures = 0;
};

TEST_F(SwapFault, DeletedSwapFilesLoseOnlyTheirBlocks) {
  const Snapshot before = snapshot(*map);
  map->dropSwapCache();
  const std::vector<BlockIndex> all = map->allBlocks();
  std::vector<BlockIndex> active;
  for (const auto& b : all) {
    if (map->isActive(b)) active.push_back(b);
  }
  const std::vector<std::string> files = swapFiles();
  ASSERT_EQ(files.size(), map->numSwappedBlocks());
  for (const auto& f : files) fs::remove(f);

  // Drive back to the start: the blocks coming back into the local map are
  // lost, nothing throws, and fusing goes on there.
  IntegrationStats stats;
  EXPECT_NO_THROW(map->moveLocalMap(Eigen::Vector3d(0, 0, 0)));
  const CameraModel cam = smallFisheye();
  EXPECT_NO_THROW(stats = map->integrate(street().render(cam, carCamera(0)), cam, carCamera(0), Eigen::Vector3d::Zero()));
  EXPECT_GT(stats.valid_pixels, 0u);
  const size_t lost_on_return = map->numLostBlocks();
  EXPECT_GT(lost_on_return, 0u);
  // A save reads every remaining swapped block: the rest of the deleted ones
  // are found lost there, and the file holds everything else.
  EXPECT_NO_THROW(map->save(dir + "/map.fmtsdf"));
  EXPECT_EQ(map->numLostBlocks(), files.size());
  EXPECT_EQ(map->numBlocks(), all.size() - files.size() + stats.blocks_allocated);
  // One message per lost block, naming its swap file.
  ASSERT_EQ(messages.size(), files.size());
  std::set<std::string> named;
  for (const auto& m : messages) {
    EXPECT_NE(m.find("lost"), std::string::npos) << m;
    for (const auto& f : files) {
      if (m.find(f + ":") != std::string::npos) named.insert(f);
    }
  }
  EXPECT_EQ(named.size(), files.size());
  // The blocks that were active when the files went (around x = 40 m, out of
  // reach of the frame at x = 0) are intact.
  size_t intact = 0;
  TsdfMap reread(smallLocalMap());
  reread.load(dir + "/map.fmtsdf");
  EXPECT_EQ(reread.numBlocks(), map->numBlocks());
  for (const auto& b : active) {
    const VoxelBlock* now = reread.block(b);
    ASSERT_NE(now, nullptr);
    if (std::memcmp(now->voxels.data(), before.at({b.x(), b.y(), b.z()}).voxels.data(), sizeof(now->voxels)) == 0) {
      ++intact;
    }
  }
  std::cout << files.size() << " swap files deleted, " << lost_on_return << " lost on the way back, "
            << active.size() << " active blocks kept, " << intact << " of them bit-identical\n";
  EXPECT_EQ(intact, active.size());
}

TEST_F(SwapFault, DamagedSwapFileLosesThatBlockOnly) {
  const Snapshot before = snapshot(*map);
  map->dropSwapCache();
  std::vector<BlockIndex> swapped;
  for (const auto& b : map->allBlocks()) {
    if (!map->isActive(b)) swapped.push_back(b);
  }
  const BlockIndex victim = swapped[swapped.size() / 2];
  const std::string path = dir + "/swap/block_" + std::to_string(victim.x()) + "_" + std::to_string(victim.y()) + "_" +
                           std::to_string(victim.z()) + ".bin";
  std::string bytes = readBytes(path);
  ASSERT_EQ(bytes.size(), 4612u);  // voxels + intensities + CRC-32
  bytes[1000] ^= 0x01;
  writeBytes(path, bytes);
  EXPECT_EQ(map->block(victim), nullptr);
  EXPECT_EQ(map->numLostBlocks(), 1u);
  ASSERT_EQ(messages.size(), 1u);
  EXPECT_NE(messages[0].find("checksum mismatch"), std::string::npos) << messages[0];
  EXPECT_NE(messages[0].find(path), std::string::npos) << messages[0];
  Snapshot expected = before;
  expected.erase({victim.x(), victim.y(), victim.z()});
  EXPECT_TRUE(sameAs(*map, expected));
  map->dropSwapCache();  // sameAs read every block
  // A truncated one, read on the way back in (a block near x = 0).
  BlockIndex second = victim;
  for (const auto& b : swapped) {
    const Eigen::Vector3d c = (b.cast<double>() + Eigen::Vector3d::Constant(0.5)) * 0.8;
    if (b != victim && std::abs(c.x()) < 8 && std::abs(c.y()) < 8 && std::abs(c.z() - 1.0) < 1.4) second = b;
  }
  ASSERT_NE(second, victim);
  const std::string path2 = dir + "/swap/block_" + std::to_string(second.x()) + "_" + std::to_string(second.y()) +
                            "_" + std::to_string(second.z()) + ".bin";
  fs::resize_file(path2, 100);
  EXPECT_NO_THROW(map->moveLocalMap(Eigen::Vector3d(0, 0, 0)));
  EXPECT_EQ(map->numLostBlocks(), 2u);
  EXPECT_FALSE(map->isActive(second));
  EXPECT_NE(messages.back().find("short file"), std::string::npos) << messages.back();
  expected.erase({second.x(), second.y(), second.z()});
  EXPECT_TRUE(sameAs(*map, expected));
}

TEST_F(SwapFault, UnwritableSwapDirectoryKeepsBlocksInRam) {
  const Snapshot before = snapshot(*map);
  map->dropSwapCache();
  std::vector<BlockIndex> active;
  for (const auto& b : map->allBlocks()) {
    if (map->isActive(b)) active.push_back(b);
  }
  const size_t swapped = map->numSwappedBlocks();
  // The swap directory becomes a plain file (its files are gone with it).
  fs::remove_all(dir + "/swap");
  writeBytes(dir + "/swap", "not a directory");
  // Driving away cannot write the active blocks out: they stay in RAM.
  EXPECT_NO_THROW(map->moveLocalMap(Eigen::Vector3d(500, 0, 0)));
  EXPECT_EQ(map->numSwapWriteFailures(), active.size());
  EXPECT_EQ(write_failures, active.size());
  EXPECT_EQ(map->numActiveBlocks(), 0u);
  for (const auto& b : active) {
    const VoxelBlock* blk = map->block(b);
    ASSERT_NE(blk, nullptr);
    ASSERT_EQ(std::memcmp(blk->voxels.data(), before.at({b.x(), b.y(), b.z()}).voxels.data(), sizeof(blk->voxels)), 0);
  }
  EXPECT_EQ(map->numLostBlocks(), 0u);
  // A save keeps them; the blocks whose files went with the directory are lost.
  EXPECT_NO_THROW(map->save(dir + "/map.fmtsdf"));
  EXPECT_EQ(map->numLostBlocks(), swapped);
  TsdfMap reread(smallLocalMap());
  reread.load(dir + "/map.fmtsdf");
  EXPECT_EQ(reread.numBlocks(), active.size());
  // Coming back: they return from RAM.
  EXPECT_NO_THROW(map->moveLocalMap(Eigen::Vector3d(40, 0, 0)));
  EXPECT_EQ(map->numActiveBlocks(), active.size());
}

// --- map_tool ----------------------------------------------------------------

struct ToolRun {
  int status;
  std::string out;
};
ToolRun runTool(const std::string& args) {
  const std::string cmd = std::string(FM_MAP_TOOL) + " " + args + " 2>&1";
  FILE* p = popen(cmd.c_str(), "r");
  ToolRun r{-1, ""};
  if (!p) return r;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof(buf), p)) > 0) r.out.append(buf, n);
  const int st = pclose(p);
  r.status = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  return r;
}

// Issue 28: map_tool applies the header ranges the nodelet's parameters have
// (truncation = 1e9 voxels was "valid" and meshed); a FIFO is refused at once.
TEST_F(MapFile, MapToolAppliesTheNodeletsHeaderRanges) {
  const std::string d = tempDir();
  const struct {
    size_t at;
    double value;
    std::string expected;
  } cases[] = {
      {20, 1e9, "bad header: truncation_voxels 1e+09 (must lie in (0, 1000] voxels)"},
      {12, 50.0, "bad header: voxel_size 50 m (must lie in (0, 10] m)"},
  };
  for (const auto& c : cases) {
    std::string b = *good_;
    put<double>(&b, c.at, c.value);
    fixHeaderCrc(&b);
    writeBytes(d + "/range.fmtsdf", b);
    for (const std::string cmd : {"check ", "info "}) {
      const ToolRun r = runTool(cmd + d + "/range.fmtsdf");
      EXPECT_EQ(r.status, 1) << r.out;
      EXPECT_NE(r.out.find(c.expected), std::string::npos) << r.out;
    }
    ToolRun r = runTool("convert " + d + "/range.fmtsdf " + d + "/range.ply");
    EXPECT_EQ(r.status, 1) << r.out;
    EXPECT_FALSE(fs::exists(d + "/range.ply"));
    // The same loader as the nodelet's (TsdfMap::readHeader).
    EXPECT_THROW(TsdfMap::readHeader(d + "/range.fmtsdf"), std::runtime_error);
  }
  // The parameter ranges are the header's.
  TsdfConfig cfg;
  cfg.truncation_voxels = 1e9;
  EXPECT_THROW(cfg.validate(), std::invalid_argument);
  cfg = TsdfConfig();
  cfg.voxel_size = 50;
  EXPECT_THROW(cfg.validate(), std::invalid_argument);
  const std::string fifo = d + "/fifo.fmtsdf";
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  const ToolRun r = runTool("check " + fifo);
  EXPECT_EQ(r.status, 1) << r.out;
  EXPECT_NE(r.out.find("is a FIFO (named pipe), not a regular file, not a map file"), std::string::npos) << r.out;
}

TEST_F(MapFile, MapToolReadsTheSameFiles) {
  const std::string d = tempDir();
  const std::string good = *dir_ + "/good.fmtsdf";
  ToolRun r = runTool("check " + good);
  EXPECT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("valid: " + good + ": format version 2, " + std::to_string(numBlocks()) + " blocks"),
            std::string::npos)
      << r.out;
  r = runTool("info " + good);
  EXPECT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("blocks (header):   " + std::to_string(numBlocks())), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("valid:             yes"), std::string::npos) << r.out;
  r = runTool("convert " + good + " " + d + "/mesh.ply");
  EXPECT_EQ(r.status, 0) << r.out;
  EXPECT_EQ(readBytes(d + "/mesh.ply").substr(0, 3), "ply");
  r = runTool("convert " + good + " " + d + "/cloud.pcd --min-observations 2");
  EXPECT_EQ(r.status, 0) << r.out;
  EXPECT_NE(readBytes(d + "/cloud.pcd").find("POINTS"), std::string::npos);
  r = runTool("check " + *dir_ + "/good3.fmtsdf");
  EXPECT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("format version 3, " + std::to_string(numBlocks()) + " blocks"), std::string::npos) << r.out;
  // A version-1 file too.
  writeBytes(d + "/v1.fmtsdf", versionOneFile(*snap_));
  EXPECT_EQ(runTool("check " + d + "/v1.fmtsdf").status, 0);

  // Bad files: exit 1 with the reason.
  std::string b = *good_;
  b[voxelAt(7, 300) + 2] ^= 0x10;
  writeBytes(d + "/flipped.fmtsdf", b);
  r = runTool("check " + d + "/flipped.fmtsdf");
  EXPECT_EQ(r.status, 1) << r.out;
  EXPECT_NE(r.out.find(blockName(b, 7) + ": checksum mismatch"), std::string::npos) << r.out;
  r = runTool("info " + d + "/flipped.fmtsdf");
  EXPECT_EQ(r.status, 1) << r.out;
  EXPECT_NE(r.out.find("valid:             no"), std::string::npos) << r.out;
  r = runTool("convert " + d + "/flipped.fmtsdf " + d + "/bad.ply");
  EXPECT_EQ(r.status, 1) << r.out;
  EXPECT_FALSE(fs::exists(d + "/bad.ply"));
  b = *good_;
  put<float>(&b, voxelAt(3, 77), NAN);
  fixBlockCrc(&b, 3);
  writeBytes(d + "/nan.fmtsdf", b);
  EXPECT_EQ(runTool("check " + d + "/nan.fmtsdf").status, 1);
  writeBytes(d + "/cut.fmtsdf", good_->substr(0, 1000));
  EXPECT_EQ(runTool("check " + d + "/cut.fmtsdf").status, 1);
  EXPECT_EQ(runTool("check " + d).status, 1);
  EXPECT_EQ(runTool("check " + d + "/missing.fmtsdf").status, 1);

  // Strict arguments: exit 2.
  for (const std::string& args :
       {std::string(""), std::string("frobnicate " + good), std::string("check"), "check " + good + " extra",
        "convert " + good, "convert " + good + " " + d + "/out.txt", "convert " + good + " " + good + ".ply extra",
        "check " + good + " --max-weight abc", "check " + good + " --max-weight", "check " + good + " --bogus",
        "info " + good + " --min-observations 2", "convert " + good + " " + d + "/m.ply --min-observations 0"}) {
    r = runTool(args);
    EXPECT_EQ(r.status, 2) << "map_tool " << args << ": " << r.out;
    EXPECT_NE(r.out.find("usage:"), std::string::npos) << r.out;
  }
  EXPECT_EQ(runTool("--help").status, 0);
  fs::remove_all(d);
}

}  // namespace
}  // namespace fisheye_mapping
