// Opening the bags users give the offline tools, as they come off a car: a
// recording cut short (power loss, a full disk, a killed `rosbag record`)
// leaves a bag without its index (`<name>.bag.active`: the header's index
// position is 0) or with an index position beyond the file's end (cut mid-chunk).
// librosbag reads only indexed bags and says "wanted 4 bytes" or "Bag
// unindexed"; these say what happened and give the exact `rosbag reindex`
// command that recovers every complete chunk.
#ifndef FISHEYE_MAPPING_ROS_BAG_READING_H_
#define FISHEYE_MAPPING_ROS_BAG_READING_H_

#include <rosbag/bag.h>

#include <string>

namespace fisheye_mapping {

/// What the bag's file header says about its index: "" when it looks whole
/// (or is no rosbag 2.0 file: librosbag then names the problem), else e.g.
/// "it has no index (a recording that was not closed: index position 0)" or
/// "it is cut short: its index should start at byte 4211 but the file has 3000 bytes".
std::string bagIndexProblem(const std::string& path);

/// The shell command that reindexes `path` in place (rosbag keeps the original
/// as <name>.orig.<ext>), the path quoted for the shell.
std::string rosbagReindexCommand(const std::string& path);

/// Opens `path` for reading: a regular file (a FIFO or a device is refused
/// without blocking) that librosbag opens. Throws std::runtime_error naming
/// the bag: for an unindexed or truncated bag, what bagIndexProblem() found
/// and rosbagReindexCommand(); otherwise librosbag's error.
void openBagForReading(rosbag::Bag& bag, const std::string& path);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_ROS_BAG_READING_H_
