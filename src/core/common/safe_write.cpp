#include "fisheye_mapping/core/common/safe_write.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <stdexcept>

#include "fisheye_mapping/core/common/paths.h"

namespace fisheye_mapping {
namespace {

namespace fs = std::filesystem;

std::string osError(int err) { return std::strerror(err); }

[[noreturn]] void fail(const std::string& name, const std::string& what) {
  throw std::runtime_error(name + ": " + what);
}

// Whether `p` is `root` or lies below it (both absolute and normal).
bool isInside(const fs::path& p, const fs::path& root) {
  const fs::path rel = p.lexically_relative(root);
  return !rel.empty() && *rel.begin() != "..";
}

// The existing part of `p` resolved through links, the rest appended.
fs::path resolvedParent(const fs::path& p) {
  std::error_code ec;
  fs::path r = fs::weakly_canonical(p, ec);
  if (ec) throw std::invalid_argument("cannot resolve the folder " + p.string() + ": " + ec.message());
  return r.lexically_normal();
}

}  // namespace

std::string confineSavePath(const std::string& requested, const SaveFolder& folder) {
  if (folder.directory.empty()) throw std::invalid_argument("no save folder is configured");
  std::error_code ec;
  const fs::path dir = fs::absolute(fs::path(folder.directory), ec).lexically_normal();
  if (ec) throw std::invalid_argument("save folder '" + folder.directory + "': " + ec.message());
  // Empty, a directory, "~" without HOME: refused here, naming the request.
  const fs::path lexical(resolveOutputPath(requested, dir.string()));
  const fs::path root = resolvedParent(dir);
  const fs::path parent = resolvedParent(lexical.parent_path());
  const bool inside = isInside(parent, root);
  if (!inside && !folder.allow_any_path) {
    const std::string where = (parent / lexical.filename()).string();
    throw std::invalid_argument("save path '" + requested + "'" + (where == requested ? "" : " (" + where + ")") +
                                " is outside the save folder " + root.string() +
                                ": give a path inside it (a relative path is taken inside it); writing anywhere "
                                "else needs allow_any_save_path (unsafe)");
  }
  if (!fs::is_directory(parent, ec)) {
    fs::create_directories(parent, ec);
    if (ec) throw std::invalid_argument("cannot create the folder " + parent.string() + ": " + ec.message());
  }
  // Once it exists, resolve it again: a link made meanwhile is seen.
  const fs::path final_parent = resolvedParent(parent);
  if (inside && !folder.allow_any_path && !isInside(final_parent, resolvedParent(dir))) {
    throw std::invalid_argument("save path '" + requested + "': its folder " + final_parent.string() +
                                " is outside the save folder " + root.string());
  }
  return (final_parent / lexical.filename()).string();
}

std::string unsafeTargetKind(const std::string& path) {
  struct stat st {};
  if (::lstat(path.c_str(), &st) != 0) return "";  // nothing there (or unreadable: the open says why)
  if (S_ISREG(st.st_mode) || S_ISLNK(st.st_mode)) return "";
  if (S_ISDIR(st.st_mode)) return "a directory";
  if (S_ISFIFO(st.st_mode)) return "a FIFO";
  if (S_ISCHR(st.st_mode)) return "a character device";
  if (S_ISBLK(st.st_mode)) return "a block device";
  if (S_ISSOCK(st.st_mode)) return "a socket";
  return "not a regular file";
}

void writeAllTo(int fd, const void* data, size_t n, const std::string& name) {
  const char* p = static_cast<const char*>(data);
  while (n > 0) {
    const ssize_t w = ::write(fd, p, n);
    if (w < 0 && errno == EINTR) continue;
    if (w < 0) fail(name, "write failed: " + osError(errno));
    if (w == 0) fail(name, "write failed: nothing written");
    p += w;
    n -= static_cast<size_t>(w);
  }
}

void syncAndClose(int fd, uint64_t expected_size, const std::string& name) {
  if (::fsync(fd) != 0) {
    const int err = errno;
    ::close(fd);
    fail(name, "write failed (fsync): " + osError(err));
  }
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    const int err = errno;
    ::close(fd);
    fail(name, "write failed (fstat): " + osError(err));
  }
  if (S_ISREG(st.st_mode) && static_cast<uint64_t>(st.st_size) != expected_size) {
    ::close(fd);
    fail(name, "write failed: the file holds " + std::to_string(st.st_size) + " bytes, " +
                   std::to_string(expected_size) + " were written");
  }
  if (::close(fd) != 0) fail(name, "write failed (close): " + osError(errno));
}

SafeFileWriter::SafeFileWriter(const std::string& path) : path_(path) {
  if (path.empty()) throw std::runtime_error("cannot save: empty path");
  const std::string kind = unsafeTargetKind(path);
  if (!kind.empty()) fail(path, "is " + kind + ", not a regular file: refused (a save replaces regular files only)");
  const fs::path p(path);
  if (!p.has_filename()) fail(path, "names a folder, not a file");
  const fs::path dir = p.has_parent_path() ? p.parent_path() : fs::path(".");
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) fail(path, "no such folder " + dir.string());
  static std::atomic<unsigned> counter{0};
  for (int attempt = 0; attempt < 100 && fd_ < 0; ++attempt) {
    tmp_ = (dir / ("." + p.filename().string() + ".tmp." + std::to_string(::getpid()) + "." +
                   std::to_string(counter++)))
               .string();
    fd_ = ::open(tmp_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0666);
    if (fd_ < 0 && errno != EEXIST) fail(path, "cannot write into " + dir.string() + ": " + osError(errno));
  }
  if (fd_ < 0) fail(path, "cannot make a temporary file in " + dir.string());
}

SafeFileWriter::~SafeFileWriter() {
  if (fd_ >= 0) ::close(fd_);
  if (!committed_ && !tmp_.empty()) ::unlink(tmp_.c_str());
}

void SafeFileWriter::write(const void* data, size_t n) {
  if (fd_ < 0) fail(path_, "write after commit");
  writeAllTo(fd_, data, n, path_);
  size_ += n;
}

void SafeFileWriter::writeAt(const void* data, size_t n, uint64_t offset) {
  if (fd_ < 0) fail(path_, "write after commit");
  if (offset + n > size_) fail(path_, "writeAt past the bytes written");
  const char* p = static_cast<const char*>(data);
  while (n > 0) {
    const ssize_t w = ::pwrite(fd_, p, n, static_cast<off_t>(offset));
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) fail(path_, "write failed: " + (w < 0 ? osError(errno) : std::string("nothing written")));
    p += w, offset += static_cast<uint64_t>(w), n -= static_cast<size_t>(w);
  }
}

void SafeFileWriter::commit(bool keep_previous) {
  if (fd_ < 0) fail(path_, "committed twice");
  const int fd = fd_;
  fd_ = -1;
  syncAndClose(fd, size_, path_);
  // What is at the target now (it may have changed while writing).
  const std::string kind = unsafeTargetKind(path_);
  if (!kind.empty()) fail(path_, "is " + kind + ", not a regular file: refused (a save replaces regular files only)");
  struct stat st {};
  if (keep_previous && ::lstat(path_.c_str(), &st) == 0 && S_ISREG(st.st_mode)) {
    // Kept as <path>.1: a hard link (atomic, no copy), else a copy.
    const std::string prev = path_ + ".1";
    std::error_code ec;
    fs::remove(prev, ec);
    if (::link(path_.c_str(), prev.c_str()) != 0) {
      ec.clear();
      fs::copy_file(path_, prev, fs::copy_options::overwrite_existing, ec);
      if (ec) fail(path_, "cannot keep the previous file as " + prev + ": " + ec.message() + "; nothing replaced");
    }
  }
  if (::rename(tmp_.c_str(), path_.c_str()) != 0) {
    fail(path_, "cannot replace it with " + tmp_ + ": " + osError(errno));
  }
  committed_ = true;
  // Make the rename durable too (best effort: some file systems refuse a
  // folder's fsync; the file itself is synced above).
  const fs::path p(path_);
  const fs::path dir = p.has_parent_path() ? p.parent_path() : fs::path(".");
  const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd >= 0) {
    ::fsync(dfd);
    ::close(dfd);
  }
}

void writeFileSafely(const std::string& path, std::string_view bytes, bool keep_previous) {
  SafeFileWriter w(path);
  w.write(bytes);
  w.commit(keep_previous);
}

std::string captureFileOutput(const std::function<void(const std::string& name)>& write) {
  const int fd = ::memfd_create("fisheye_mapping_capture", MFD_CLOEXEC);
  if (fd < 0) throw std::runtime_error("cannot make an in-memory file: " + osError(errno));
  struct Closer {
    int fd;
    ~Closer() { ::close(fd); }
  } closer{fd};
  write("/proc/self/fd/" + std::to_string(fd));
  struct stat st {};
  if (::fstat(fd, &st) != 0) throw std::runtime_error("cannot read the in-memory file: " + osError(errno));
  std::string bytes(static_cast<size_t>(st.st_size), '\0');
  size_t got = 0;
  while (got < bytes.size()) {
    const ssize_t r = ::pread(fd, &bytes[got], bytes.size() - got, static_cast<off_t>(got));
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) throw std::runtime_error("cannot read the in-memory file: " + (r < 0 ? osError(errno) : "short"));
    got += static_cast<size_t>(r);
  }
  return bytes;
}

}  // namespace fisheye_mapping
