// Writing files safely: where a client-named file may be written (the save
// folder), and a writer that never follows a link at the target, never writes
// into a FIFO or a device, and never reports a write it did not make (every
// write, the fsync, the size and the close checked; the file appears under
// its name only complete, by a rename in its folder).
// Reading files is not here.
#ifndef FISHEYE_MAPPING_CORE_COMMON_SAFE_WRITE_H_
#define FISHEYE_MAPPING_CORE_COMMON_SAFE_WRITE_H_

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <string_view>

namespace fisheye_mapping {

// The folder the save services and automatic saves write into.
struct SaveFolder {
  std::string directory;        // absolute, or relative to the current directory
  bool allow_any_path = false;  // UNSAFE: an absolute path anywhere is written (relative ones still go inside)
};

// The absolute path a requested save writes to: "~/" expanded, a relative
// path taken inside folder.directory, "." and ".." folded, the existing part
// of its parent resolved through symbolic links (so a link inside the folder
// that points out of it is seen). Unless folder.allow_any_path, a path that
// ends outside the folder is refused (std::invalid_argument naming the
// request and the folder), as are an empty path and a directory
// (resolveOutputPath). Missing folders (the save folder itself, or a
// subfolder of the request inside it) are created. The file itself is not
// looked at: SafeFileWriter refuses what is no regular file.
std::string confineSavePath(const std::string& requested, const SaveFolder& folder);

// What lies at `path` when it is something a save must not replace: "" for
// nothing, a regular file or a symbolic link (which a save replaces, never
// follows), else "a FIFO", "a character device", "a directory", ...
std::string unsafeTargetKind(const std::string& path);

// A new file written beside `path` (same folder, O_EXCL, not following
// links) and renamed over it by commit(); dropped (nothing at `path`
// changes) when the writer goes without commit(). Every failure throws
// std::runtime_error naming `path` and the OS error (e.g. "No space left on
// device"). The constructor refuses a target that is a FIFO, a device, a
// directory or a socket, and a missing folder.
class SafeFileWriter {
 public:
  explicit SafeFileWriter(const std::string& path);
  ~SafeFileWriter();
  SafeFileWriter(const SafeFileWriter&) = delete;
  SafeFileWriter& operator=(const SafeFileWriter&) = delete;

  void write(const void* data, size_t n);
  void write(std::string_view bytes) { write(bytes.data(), bytes.size()); }
  // Overwrites bytes already written (offset + n <= size()).
  void writeAt(const void* data, size_t n, uint64_t offset);
  uint64_t size() const { return size_; }
  const std::string& path() const { return path_; }
  const std::string& tempPath() const { return tmp_; }

  // Flushes to disk (fsync), checks the file's size against the bytes
  // written, closes (checked), then renames it over `path` (a link there is
  // replaced; its target is untouched) and syncs the folder. keep_previous:
  // a regular file at `path` is kept as <path>.1 first (a hard link, else a
  // copy), replacing an older .1.
  void commit(bool keep_previous = false);

 private:
  std::string path_, tmp_;
  int fd_ = -1;
  uint64_t size_ = 0;
  bool committed_ = false;
};

// SafeFileWriter for bytes in memory.
void writeFileSafely(const std::string& path, std::string_view bytes, bool keep_previous = false);

// The checked steps on an open file descriptor (`name` in the messages):
// every byte written (short writes and EINTR retried), then fsync, the size
// (fstat, regular files) against `expected_size`, and close. Each throws
// std::runtime_error with the OS error; syncAndClose closes fd in any case.
void writeAllTo(int fd, const void* data, size_t n, const std::string& name);
void syncAndClose(int fd, uint64_t expected_size, const std::string& name);

// The bytes a library writer that only takes a file name (PCL's PLY writer)
// writes: `write` is given the name of an in-memory file. Throws
// std::runtime_error when no such file can be made or read.
std::string captureFileOutput(const std::function<void(const std::string& name)>& write);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_COMMON_SAFE_WRITE_H_
